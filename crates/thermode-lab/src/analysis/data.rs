//! Reading session CSVs: one row per trial, header first (PsychoPy's conventions), and the CSV checks shared with the
//! curve files.
//!
//! Required columns: `participant`, `condition` (`real` or `simulated`, case-insensitive, trimmed), `presented`,
//! `identified` (material names as the model library knows them, see `thermode_model::materials::find`; spelling
//! variants it accepts, such as `Aluminum`, are mapped to the library name). Optional: `excluded` (`true`/`false`/
//! `1`/`0`/`yes`/`no`/empty, case-insensitive): excluded trials are left out of every statistic and counted; only
//! their `excluded` field is checked. Header names are matched trimmed and case-insensitively; every other column
//! is kept with the trial (and echoed in `trials.csv`) but ignored by the statistics.
//!
//! The response options are the set of materials presented anywhere in the data (excluded trials too: their materials were offered all the same); an identified material
//! outside that set is an error. The options are ordered by conductivity, highest first (the paper's Table 1 order:
//! aluminium, steel, stone, wood, rubber), ties by name.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use serde::Serialize;
use thermode_model::materials::find;
use thermode_model::units::{conductivity_to_cgs, specific_heat_to_cgs};
use thermode_model::ParamError;
use thermode_platform::fs::{open_at_most, MAX_DATA_BYTES};

use crate::design::Condition;
use crate::error::LabError;

/// A response option: a library material with the two properties of the paper's Figure 4 in the paper's units.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialInfo {
    /// Library name, or the name of a custom material whose properties its file names.
    pub name: String,
    /// Thermal conductivity k [cal/(cm·s·°C)] (the library's SI value converted).
    pub conductivity_cal_cm_s_c: f64,
    /// Specific heat capacity c [cal/(g·°C)] (the library's SI value converted).
    pub specific_heat_cal_g_c: f64,
}

/// One included trial.
#[derive(Debug, Clone, PartialEq)]
pub struct Trial {
    /// The session file it came from.
    pub file: PathBuf,
    /// 1-based line in that file.
    pub line: u64,
    /// Participant identifier (trimmed).
    pub participant: String,
    /// Real or simulated.
    pub condition: Condition,
    /// Library name of the presented material.
    pub presented: String,
    /// Library name of the identified material.
    pub identified: String,
    /// Every column of the row as read (header name, value), the required ones included.
    pub fields: Vec<(String, String)>,
}

/// All session files read and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct Sessions {
    /// The files, in the order given.
    pub files: Vec<PathBuf>,
    /// The included trials, file by file in row order.
    pub trials: Vec<Trial>,
    /// Number of rows marked excluded.
    pub excluded_trials: usize,
    /// The response options (every presented material), by conductivity, highest first.
    pub materials: Vec<MaterialInfo>,
    /// The union of the files' column names, in order of first appearance.
    pub columns: Vec<String>,
}

impl Sessions {
    /// Index of a material name in [`Sessions::materials`].
    pub fn material_index(&self, name: &str) -> Option<usize> {
        self.materials.iter().position(|m| m.name == name)
    }
}

/// A CSV file checked for shape: header, rows of the header's length, at least one row.
#[derive(Debug, Clone)]
pub(crate) struct CsvTable {
    pub file: PathBuf,
    /// Header names as written (trimmed, byte-order mark removed).
    pub header: Vec<String>,
    /// (1-based line, fields) of every data row.
    pub rows: Vec<(u64, Vec<String>)>,
}

impl CsvTable {
    /// Reads `path`; a row with a different number of fields than the header or a file without data rows is an
    /// error naming the file (and line).
    pub fn read(path: &Path) -> Result<CsvTable, LabError> {
        if thermode_table::Format::of(path).is_columnar() {
            return CsvTable::read_columnar(path);
        }
        let file = open_at_most(path, MAX_DATA_BYTES).map_err(|e| LabError::io(path, e))?;
        let mut reader = csv::ReaderBuilder::new()
            .flexible(true)
            .has_headers(true)
            .from_reader(file);
        let csv_error = |e: csv::Error| LabError::Csv {
            file: path.to_path_buf(),
            line: e.position().map(csv::Position::line),
            message: e.to_string(),
        };
        let header: Vec<String> = reader
            .headers()
            .map_err(csv_error)?
            .iter()
            .map(|h| h.trim_start_matches('\u{feff}').trim().to_string())
            .collect();
        let mut rows = Vec::new();
        for record in reader.records() {
            let record = record.map_err(csv_error)?;
            let line = record.position().map_or(0, csv::Position::line);
            if record.len() != header.len() {
                return Err(LabError::MalformedRow {
                    file: path.to_path_buf(),
                    line,
                    expected: header.len(),
                    found: record.len(),
                });
            }
            rows.push((line, record.iter().map(str::to_string).collect()));
        }
        CsvTable::checked(path, header, rows)
    }

    /// The table of `path`, unless it has no data row or no column name (an error naming the file).
    fn checked(path: &Path, header: Vec<String>, rows: Vec<(u64, Vec<String>)>) -> Result<CsvTable, LabError> {
        if rows.is_empty() || header.iter().all(String::is_empty) {
            return Err(LabError::EmptyFile {
                file: path.to_path_buf(),
            });
        }
        Ok(CsvTable {
            file: path.to_path_buf(),
            header,
            rows,
        })
    }

    /// Reads an Arrow IPC (`.arrow`, `.feather`) or Parquet (`.parquet`) file that `simulate` or `render` wrote:
    /// each value as the field the CSV holds (floats in their shortest exact form, null as an empty field), so
    /// every reader of thermode's CSVs reads these too; rows are numbered as the CSV's lines would be.
    fn read_columnar(path: &Path) -> Result<CsvTable, LabError> {
        let (header, rows) = thermode_table::read_fields(path, MAX_DATA_BYTES).map_err(|e| LabError::Csv {
            file: path.to_path_buf(),
            line: None,
            message: e.to_string(),
        })?;
        let rows = rows.into_iter().zip(2..).map(|(fields, line)| (line, fields)).collect();
        CsvTable::checked(path, header, rows)
    }

    /// Index of the column `name` (case-insensitive); `None` if absent, an error if it appears twice.
    pub fn optional_column(&self, name: &str) -> Result<Option<usize>, LabError> {
        let mut hits = self
            .header
            .iter()
            .enumerate()
            .filter(|(_, h)| h.eq_ignore_ascii_case(name))
            .map(|(i, _)| i);
        let first = hits.next();
        if hits.next().is_some() {
            return Err(LabError::DuplicateColumn {
                file: self.file.clone(),
                column: name.to_string(),
            });
        }
        Ok(first)
    }

    /// Index of the required column `name`.
    pub fn column(&self, name: &str) -> Result<usize, LabError> {
        self.optional_column(name)?.ok_or_else(|| LabError::MissingColumn {
            file: self.file.clone(),
            column: name.to_string(),
        })
    }

    /// An error for the field `column` of the row at `line`.
    pub fn bad_value(&self, line: u64, column: &str, value: &str, expected: &str) -> LabError {
        LabError::BadField {
            file: self.file.clone(),
            line,
            column: column.to_string(),
            value: value.to_string(),
            expected: expected.to_string(),
        }
    }
}

/// Looks material names up in the model library once per distinct spelling.
#[derive(Debug, Default)]
pub(crate) struct MaterialResolver {
    cache: HashMap<String, Result<MaterialInfo, Vec<String>>>,
}

impl MaterialResolver {
    /// The library material called `value`; on failure, the close library names.
    pub fn resolve(&mut self, value: &str) -> Result<MaterialInfo, Vec<String>> {
        self.cache
            .entry(value.to_string())
            .or_insert_with(|| lookup(value))
            .clone()
    }

    /// Like [`MaterialResolver::resolve`], with the error naming the file, line and column.
    pub fn resolve_at(
        &mut self,
        table: &CsvTable,
        line: u64,
        column: &str,
        value: &str,
    ) -> Result<MaterialInfo, LabError> {
        self.resolve(value).map_err(|close| LabError::UnknownMaterial {
            file: table.file.clone(),
            line,
            column: column.to_string(),
            value: value.to_string(),
            close,
        })
    }
}

/// The columns of a curve file that name the touched material's properties (a `serve --record` file since issue 25:
/// `conductivity_w_mk` and `specific_heat_j_kgk`, SI, empty outside a touch). A row that fills them needs no library:
/// a custom material reads back by the properties its recording names.
#[derive(Debug, Clone, Copy)]
pub(crate) struct PropertyColumns {
    conductivity: usize,
    specific_heat: usize,
}

impl PropertyColumns {
    /// The property columns of `table`, if it has both.
    pub fn of(table: &CsvTable) -> Result<Option<PropertyColumns>, LabError> {
        Ok(
            match (
                table.optional_column("conductivity_w_mk")?,
                table.optional_column("specific_heat_j_kgk")?,
            ) {
                (Some(conductivity), Some(specific_heat)) => Some(PropertyColumns {
                    conductivity,
                    specific_heat,
                }),
                _ => None,
            },
        )
    }

    /// The material `name` with the properties of the row at `line`, or `None` if the row leaves them empty.
    fn info(
        &self,
        table: &CsvTable,
        line: u64,
        name: &str,
        fields: &[String],
    ) -> Result<Option<MaterialInfo>, LabError> {
        let (k, c) = (fields[self.conductivity].trim(), fields[self.specific_heat].trim());
        if k.is_empty() && c.is_empty() {
            return Ok(None);
        }
        let positive = |column: &str, text: &str| match text.parse::<f64>() {
            Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
            _ => Err(table.bad_value(line, column, text, "a positive number (SI)")),
        };
        Ok(Some(MaterialInfo {
            name: name.trim().to_string(),
            conductivity_cal_cm_s_c: conductivity_to_cgs(positive("conductivity_w_mk", k)?),
            specific_heat_cal_g_c: specific_heat_to_cgs(positive("specific_heat_j_kgk", c)?),
        }))
    }
}

impl MaterialResolver {
    /// The material of the row at `line`: by the properties the row names (`properties`), else from the library by
    /// the name in `column`.
    pub fn resolve_row(
        &mut self,
        table: &CsvTable,
        line: u64,
        (column, index): (&str, usize),
        fields: &[String],
        properties: Option<PropertyColumns>,
    ) -> Result<MaterialInfo, LabError> {
        let named = match properties {
            Some(p) if !fields[index].trim().is_empty() => p.info(table, line, &fields[index], fields)?,
            _ => None,
        };
        match named {
            Some(info) => Ok(info),
            None => self.resolve_at(table, line, column, &fields[index]),
        }
    }
}

fn lookup(value: &str) -> Result<MaterialInfo, Vec<String>> {
    if value.trim().is_empty() {
        return Err(Vec::new());
    }
    match find(value) {
        Ok(m) => Ok(MaterialInfo {
            name: m.name,
            conductivity_cal_cm_s_c: conductivity_to_cgs(m.conductivity_w_mk),
            specific_heat_cal_g_c: specific_heat_to_cgs(m.specific_heat_j_kgk),
        }),
        Err(ParamError::UnknownMaterial { close, .. }) => Err(close),
        Err(_) => Err(Vec::new()),
    }
}

/// Parses the `excluded` field: true/false/1/0/yes/no (any case) or empty (= not excluded).
fn parse_excluded(text: &str) -> Option<bool> {
    match text.trim().to_ascii_lowercase().as_str() {
        "true" | "1" | "yes" => Some(true),
        "false" | "0" | "no" | "" => Some(false),
        _ => None,
    }
}

/// The required columns of a session file.
pub const REQUIRED_COLUMNS: [&str; 4] = ["participant", "condition", "presented", "identified"];

/// Column indexes of one session file.
struct SessionColumns {
    participant: usize,
    condition: usize,
    presented: usize,
    identified: usize,
    excluded: Option<usize>,
}

impl SessionColumns {
    fn of(table: &CsvTable) -> Result<SessionColumns, LabError> {
        Ok(SessionColumns {
            participant: table.column("participant")?,
            condition: table.column("condition")?,
            presented: table.column("presented")?,
            identified: table.column("identified")?,
            excluded: table.optional_column("excluded")?,
        })
    }
}

/// Reads and checks session CSVs (see the module documentation for the format).
pub fn read_sessions(paths: &[PathBuf]) -> Result<Sessions, LabError> {
    if paths.is_empty() {
        return Err(LabError::NoData("no session file given".to_string()));
    }
    let mut resolver = MaterialResolver::default();
    let mut trials = Vec::new();
    let mut excluded_trials = 0;
    let mut columns: Vec<String> = Vec::new();
    let mut presented: HashMap<String, MaterialInfo> = HashMap::new();
    for path in paths {
        let table = CsvTable::read(path)?;
        for name in &table.header {
            if !columns.contains(name) {
                columns.push(name.clone());
            }
        }
        let (file_trials, excluded) = read_trials(&table, &mut resolver, &mut presented)?;
        trials.extend(file_trials);
        excluded_trials += excluded;
    }
    if trials.is_empty() {
        let files: Vec<String> = paths.iter().map(|p| p.display().to_string()).collect();
        return Err(LabError::NoData(format!(
            "{}: all {excluded_trials} trials are excluded; nothing to analyse",
            files.join(", ")
        )));
    }
    check_identified_are_options(&trials, &presented)?;
    let mut materials: Vec<MaterialInfo> = presented.into_values().collect();
    materials.sort_by(|a, b| {
        b.conductivity_cal_cm_s_c
            .total_cmp(&a.conductivity_cal_cm_s_c)
            .then(a.name.cmp(&b.name))
    });
    Ok(Sessions {
        files: paths.to_vec(),
        trials,
        excluded_trials,
        materials,
        columns,
    })
}

/// The included trials of one file and its number of excluded rows; records every presented material.
fn read_trials(
    table: &CsvTable,
    resolver: &mut MaterialResolver,
    presented: &mut HashMap<String, MaterialInfo>,
) -> Result<(Vec<Trial>, usize), LabError> {
    let cols = SessionColumns::of(table)?;
    let mut trials = Vec::new();
    let mut excluded = 0;
    for (line, fields) in &table.rows {
        let line = *line;
        if let Some(i) = cols.excluded {
            let value = &fields[i];
            let is_excluded = parse_excluded(value)
                .ok_or_else(|| table.bad_value(line, "excluded", value, "expected true/false/1/0/yes/no or empty"))?;
            if is_excluded {
                // Its material was still presented: it stays a response option.
                let shown = resolver.resolve_at(table, line, "presented", &fields[cols.presented])?;
                presented.entry(shown.name.clone()).or_insert(shown);
                excluded += 1;
                continue;
            }
        }
        let participant = fields[cols.participant].trim().to_string();
        if participant.is_empty() {
            return Err(table.bad_value(line, "participant", "", "a participant identifier is required"));
        }
        let condition_text = &fields[cols.condition];
        let condition = Condition::parse(condition_text).ok_or_else(|| LabError::BadCondition {
            file: table.file.clone(),
            line,
            value: condition_text.clone(),
        })?;
        let shown = resolver.resolve_at(table, line, "presented", &fields[cols.presented])?;
        let answer = resolver.resolve_at(table, line, "identified", &fields[cols.identified])?;
        presented.entry(shown.name.clone()).or_insert_with(|| shown.clone());
        trials.push(Trial {
            file: table.file.clone(),
            line,
            participant,
            condition,
            presented: shown.name,
            identified: answer.name,
            fields: table.header.iter().cloned().zip(fields.iter().cloned()).collect(),
        });
    }
    Ok((trials, excluded))
}

/// Every identified material must be one of the presented ones (the response options).
fn check_identified_are_options(trials: &[Trial], presented: &HashMap<String, MaterialInfo>) -> Result<(), LabError> {
    match trials.iter().find(|t| !presented.contains_key(&t.identified)) {
        None => Ok(()),
        Some(t) => {
            let mut options: Vec<String> = presented.keys().cloned().collect();
            options.sort();
            Err(LabError::NotAnOption {
                file: t.file.clone(),
                line: t.line,
                value: t.identified.clone(),
                options,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn conditions_parse_trimmed_in_any_case() {
        assert_eq!(Condition::parse(" Real "), Some(Condition::Real));
        assert_eq!(Condition::parse("SIMULATED"), Some(Condition::Simulated));
        assert_eq!(Condition::parse("sim"), None);
    }

    #[test]
    fn excluded_flags() {
        assert_eq!(parse_excluded("TRUE"), Some(true));
        assert_eq!(parse_excluded(" 0 "), Some(false));
        assert_eq!(parse_excluded(""), Some(false));
        assert_eq!(parse_excluded("maybe"), None);
    }

    #[test]
    fn library_values_are_the_papers_table_1_in_cgs() {
        let al = lookup("Aluminum").expect("alias of aluminium");
        assert_eq!(al.name, "aluminium");
        assert!(
            (al.conductivity_cal_cm_s_c - 0.526).abs() < 1e-12,
            "k {}",
            al.conductivity_cal_cm_s_c
        );
        assert!(
            (al.specific_heat_cal_g_c - 0.215).abs() < 1e-12,
            "c {}",
            al.specific_heat_cal_g_c
        );
        assert!(lookup("unobtainium").is_err());
        assert!(lookup("  ").is_err());
    }
}
