//! Where the participant's answers come from: the experimenter typing them ([`InteractiveResponder`]), a file of
//! answers ([`ScriptedResponses`]) or the simulated participant ([`SimulatedParticipant`]).
//!
//! An answer is an option number 1..n (the order of the design's `response_options`) or an option's name (any
//! case; library aliases such as `aluminum` accepted).

use std::path::{Path, PathBuf};

use thermode_model::materials::find;
use thermode_platform::fs::{read_text_at_most, MAX_SETTINGS_BYTES};

use super::console::Console;
use super::stimulus::{SkinCurve, TrialMeasurement};
use super::RunError;
use crate::participant::SimulatedParticipant;
use crate::perception::PerceptualParticipant;
use crate::plan::PlannedTrial;

/// What a responder is asked for one trial.
#[derive(Debug, Clone, Copy)]
pub struct ResponseQuery<'a> {
    /// 0-based index of the participant in the design.
    pub participant_index: usize,
    /// The trial.
    pub trial: &'a PlannedTrial,
    /// The response options, in key order.
    pub options: &'a [String],
    /// What the stimulus measured.
    pub measurement: &'a TrialMeasurement,
}

/// Gives the participant's answer to a trial.
pub trait Responder {
    /// The chosen option, 0-based in `query.options`.
    fn respond(&mut self, query: &ResponseQuery, console: &mut dyn Console) -> Result<usize, RunError>;

    /// Whether the answer comes from a person at the terminal, so that the time it took is a response time. A
    /// responses file or the simulated participant answers at once: their rows leave `response_time_s` empty.
    fn is_a_person(&self) -> bool {
        false
    }
}

/// Reads an answer (`1..n` or a name) against `options`; the error says what is expected.
pub fn parse_answer(text: &str, options: &[String]) -> Result<usize, String> {
    let text = text.trim();
    if let Ok(number) = text.parse::<usize>() {
        if (1..=options.len()).contains(&number) {
            return Ok(number - 1);
        }
    }
    let by_name = options.iter().position(|o| o.eq_ignore_ascii_case(text)).or_else(|| {
        let name = find(text).ok()?.name;
        options.iter().position(|o| *o == name)
    });
    by_name.ok_or_else(|| {
        format!(
            "`{text}` is not an option: answer 1-{} or a name ({})",
            options.len(),
            options.join(", ")
        )
    })
}

/// The experimenter types the participant's answer; a bad answer is asked again.
#[derive(Debug, Default, Clone, Copy)]
pub struct InteractiveResponder;

impl Responder for InteractiveResponder {
    fn is_a_person(&self) -> bool {
        true
    }

    fn respond(&mut self, query: &ResponseQuery, console: &mut dyn Console) -> Result<usize, RunError> {
        let menu: Vec<String> = query
            .options
            .iter()
            .enumerate()
            .map(|(i, o)| format!("{} {o}", i + 1))
            .collect();
        let prompt = format!("Answer [{}]: ", menu.join(", "));
        loop {
            let Some(line) = console.ask(&prompt).map_err(RunError::Console)? else {
                return Err(RunError::InputClosed);
            };
            match parse_answer(&line, query.options) {
                Ok(choice) => return Ok(choice),
                Err(message) => console.say(&message).map_err(RunError::Console)?,
            }
        }
    }
}

/// Answers read from a file, one per trial in trial order: answer k belongs to trial k, so a resumed session uses
/// the same answers.
///
/// The file is either plain text — one answer per line, blank lines and lines starting with `#` skipped — or a CSV
/// whose header has an `identified` column (e.g. a previous session file), one row per trial.
#[derive(Debug, Clone, PartialEq)]
pub struct ScriptedResponses {
    file: PathBuf,
    /// (1-based line in the file, 0-based option).
    answers: Vec<(usize, usize)>,
}

impl ScriptedResponses {
    /// Reads and checks the answers of `path` against `options`; there must be exactly `trials` of them.
    pub fn load(path: &Path, options: &[String], trials: usize) -> Result<ScriptedResponses, RunError> {
        let text = read_text_at_most(path, MAX_SETTINGS_BYTES).map_err(|e| RunError::Responses {
            file: path.to_path_buf(),
            line: None,
            message: e.to_string(),
        })?;
        Self::from_text(&text, path, options, trials)
    }

    /// Like [`ScriptedResponses::load`] on text already read; `file` names it in errors.
    pub fn from_text(
        text: &str,
        file: &Path,
        options: &[String],
        trials: usize,
    ) -> Result<ScriptedResponses, RunError> {
        let error = |line: Option<usize>, message: String| RunError::Responses {
            file: file.to_path_buf(),
            line,
            message,
        };
        let raw = answer_lines(text).map_err(|(line, m)| error(line, m))?;
        let answers: Vec<(usize, usize)> = raw
            .into_iter()
            .map(|(line, answer)| {
                parse_answer(&answer, options)
                    .map(|a| (line, a))
                    .map_err(|m| error(Some(line), m))
            })
            .collect::<Result<_, _>>()?;
        if answers.len() != trials {
            return Err(error(
                None,
                format!("has {} answers for {trials} trials", answers.len()),
            ));
        }
        Ok(ScriptedResponses {
            file: file.to_path_buf(),
            answers,
        })
    }
}

/// A problem in a responses file: (1-based line if known, message).
type LineError = (Option<usize>, String);

/// The answer lines of a responses file: (1-based line, text).
fn answer_lines(text: &str) -> Result<Vec<(usize, String)>, LineError> {
    let lines: Vec<(usize, &str)> = text
        .lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
        .collect();
    let Some(&(_, first)) = lines.first() else {
        return Ok(Vec::new());
    };
    if !first.contains(',') {
        return Ok(lines.into_iter().map(|(i, l)| (i, l.to_string())).collect());
    }
    let mut reader = csv::ReaderBuilder::new().has_headers(true).from_reader(text.as_bytes());
    let header = reader.headers().map_err(|e| (Some(1), e.to_string()))?.clone();
    let column = header
        .iter()
        .position(|h| h.trim().eq_ignore_ascii_case("identified"))
        .ok_or((Some(1), "a CSV of responses needs an `identified` column".to_string()))?;
    reader
        .records()
        .map(|record| {
            let record = record.map_err(|e| (e.position().map(|p| p.line() as usize), e.to_string()))?;
            let line = record.position().map_or(0, |p| p.line() as usize);
            let value = record.get(column).ok_or((Some(line), "row too short".to_string()))?;
            Ok((line, value.to_string()))
        })
        .collect()
}

impl Responder for ScriptedResponses {
    fn respond(&mut self, query: &ResponseQuery, _console: &mut dyn Console) -> Result<usize, RunError> {
        let &(line, answer) =
            self.answers
                .get(query.trial.trial.wrapping_sub(1))
                .ok_or_else(|| RunError::Responses {
                    file: self.file.clone(),
                    line: None,
                    message: format!("no answer for trial {}", query.trial.trial),
                })?;
        if answer >= query.options.len() {
            return Err(RunError::Responses {
                file: self.file.clone(),
                line: Some(line),
                message: "the answer is not among the trial's options".to_string(),
            });
        }
        Ok(answer)
    }
}

/// The trial's skin curve, once the simulated participant's `options` are checked to be the query's.
fn simulated_curve<'a>(options: &[String], query: &ResponseQuery<'a>) -> Result<&'a SkinCurve, RunError> {
    if options != query.options {
        let requirement = "the simulated participant's references must be the experiment's response options, in order";
        let refused = thermode_model::params::BadValue::custom("options", options.len() as f64, requirement);
        return Err(RunError::Participant(refused.into()));
    }
    Ok(query
        .measurement
        .curve
        .as_ref()
        .ok_or(crate::participant::ParticipantError::NoCurve)?)
}

impl Responder for SimulatedParticipant {
    fn respond(&mut self, query: &ResponseQuery, _console: &mut dyn Console) -> Result<usize, RunError> {
        let curve = simulated_curve(self.options(), query)?;
        Ok(self.identify_trial(curve, query.participant_index, query.trial.trial)?)
    }
}

impl Responder for PerceptualParticipant {
    fn respond(&mut self, query: &ResponseQuery, _console: &mut dyn Console) -> Result<usize, RunError> {
        let curve = simulated_curve(self.options(), query)?;
        let features = crate::participant::CurveFeatures::of(curve)?;
        // A presented material that is not an option (never in a valid design) gets no non-thermal cue.
        let presented = self
            .options()
            .iter()
            .position(|o| *o == query.trial.presented)
            .unwrap_or(usize::MAX);
        let trial = query.trial;
        Ok(PerceptualParticipant::respond(
            self,
            &features,
            presented,
            trial.condition,
            query.participant_index,
            trial.trial,
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn options() -> Vec<String> {
        ["aluminium", "steel", "wood"].iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn answers_are_numbers_or_names() {
        let o = options();
        assert_eq!(parse_answer(" 2 ", &o), Ok(1));
        assert_eq!(parse_answer("WOOD", &o), Ok(2));
        assert_eq!(parse_answer("aluminum", &o), Ok(0));
        for bad in ["0", "4", "", "stone", "x"] {
            let err = parse_answer(bad, &o).expect_err(bad);
            assert!(err.contains("1-3"), "{err}");
        }
    }

    #[test]
    fn plain_and_csv_files() {
        let o = options();
        let f = Path::new("r.txt");
        let plain = ScriptedResponses::from_text("# answers\n1\n\nsteel\n3\n", f, &o, 3).expect("valid");
        assert_eq!(plain.answers, vec![(2, 0), (4, 1), (5, 2)]);
        let csv = "participant,identified\np,wood\np,2\n";
        let from_csv = ScriptedResponses::from_text(csv, f, &o, 2).expect("valid");
        assert_eq!(from_csv.answers, vec![(2, 2), (3, 1)]);
    }

    #[test]
    fn bad_files_name_file_and_line() {
        let o = options();
        let f = Path::new("r.txt");
        let err = ScriptedResponses::from_text("1\nstone\n", f, &o, 2)
            .expect_err("stone")
            .to_string();
        assert!(err.starts_with("r.txt:2:") && err.contains("stone"), "{err}");
        let err = ScriptedResponses::from_text("1\n2\n", f, &o, 3)
            .expect_err("count")
            .to_string();
        assert!(err.contains("2 answers for 3 trials"), "{err}");
        let err = ScriptedResponses::from_text("a,b\n1,2\n", f, &o, 1)
            .expect_err("column")
            .to_string();
        assert!(err.contains("identified"), "{err}");
    }
}
