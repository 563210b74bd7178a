//! Progress of long work on the operator's terminal: a `lab run` batch, `identify`, `tune`, a render, a display
//! trial's rest measurement. A bar (or, where the amount of work is not known, a spinner) on standard error with the
//! elapsed time and an estimate of the rest, drawn only when standard error is a terminal: piped or tested output
//! stays exactly as it was (lines a command prints go through [`Progress::line`], above the bar or as before).

use std::io::IsTerminal;
use std::time::Duration;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressFinish, ProgressStyle};

/// How often a spinner redraws on its own \[ms\]: 200.
const SPINNER_TICK_MS: u64 = 200;

/// A progress bar or spinner on standard error (hidden unless it is a terminal).
#[derive(Debug, Clone)]
pub struct Progress {
    bar: ProgressBar,
}

impl Progress {
    /// A bar of `steps` steps (`unit` names them, e.g. `sessions`) labelled `what`.
    pub fn bar(steps: u64, unit: &str, what: &str) -> Progress {
        let bar = new_bar(Some(steps));
        let template =
            format!("{{msg}} [{{bar:30}}] {{pos}}/{{len}} {unit}, {{elapsed_precise}} elapsed, about {{eta}} left");
        bar.set_style(style(&template));
        bar.set_message(what.to_string());
        Progress { bar }
    }

    /// A bar over `total_s` seconds of work (rest, excitation) labelled `what`, advanced with [`Progress::at_s`].
    pub fn seconds(total_s: f64, what: &str) -> Progress {
        let bar = new_bar(Some(tenths(total_s)));
        bar.set_style(style("{msg} [{bar:30}] {elapsed_precise} elapsed, about {eta} left"));
        bar.set_message(what.to_string());
        Progress { bar }
    }

    /// A spinner with the elapsed time, for work whose amount is not known in advance, labelled `what`.
    pub fn spinner(what: &str) -> Progress {
        let bar = new_bar(None);
        bar.set_style(style("{spinner} {msg} {elapsed_precise} elapsed"));
        bar.set_message(what.to_string());
        bar.enable_steady_tick(Duration::from_millis(SPINNER_TICK_MS));
        Progress { bar }
    }

    /// One more step done.
    pub fn step(&self) {
        self.bar.inc(1);
    }

    /// `done` steps done in all.
    pub fn at(&self, done: u64) {
        self.bar.set_position(done);
    }

    /// `done_s` seconds of a [`Progress::seconds`] bar done.
    pub fn at_s(&self, done_s: f64) {
        self.bar.set_position(tenths(done_s));
    }

    /// Prints `line` on standard error: above the bar on a terminal, as a plain line otherwise.
    pub fn line(&self, line: &str) {
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }

    /// Removes the bar (the work is done or failed).
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// A bar of `steps` (a spinner without) that clears itself when dropped, also after an error.
fn new_bar(steps: Option<u64>) -> ProgressBar {
    ProgressBar::with_draw_target(steps, target()).with_finish(ProgressFinish::AndClear)
}

/// Standard error when it is a terminal, else nothing.
fn target() -> ProgressDrawTarget {
    if std::io::stderr().is_terminal() {
        ProgressDrawTarget::stderr()
    } else {
        ProgressDrawTarget::hidden()
    }
}

fn style(template: &str) -> ProgressStyle {
    // The templates are constants of this module; a bad one falls back to indicatif's default bar.
    ProgressStyle::with_template(template)
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> ")
}

/// Tenths of `seconds`, as bar steps (a negative or non-finite time counts as 0).
fn tenths(seconds: f64) -> u64 {
    if seconds.is_finite() && seconds > 0.0 {
        (seconds * 10.0).round() as u64
    } else {
        0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn without_a_terminal_nothing_is_drawn_and_lines_stay_lines() {
        // `cargo test` captures standard error: it is not a terminal, so every bar is hidden.
        for progress in [
            Progress::bar(3, "sessions", "batch"),
            Progress::seconds(30.0, "rest"),
            Progress::spinner("fit"),
        ] {
            assert!(progress.bar.is_hidden(), "a bar drawn without a terminal");
            progress.step();
            progress.at(2);
            progress.at_s(1.5);
            progress.finish();
        }
        assert_eq!((tenths(1.26), tenths(-1.0), tenths(f64::NAN)), (13, 0, 0));
    }
}
