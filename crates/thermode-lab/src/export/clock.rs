//! The one clock of an exported session: the loop clock of the display the session ran on. A display session's
//! trial curves carry `loop_time_s` (the daemon's loop time of every sample) and its sidecar the wall-clock time of
//! loop time zero (`device.loop_time_zero_unix_s`); a `serve --record` file's `time_s` is the loop time of the daemon
//! that wrote it, its `.clock.json` the wall-clock time of that zero. On that clock, onset 0 is the first trial's
//! start: events and signals of the session share one time axis.

use std::path::Path;

use serde_json::Value;
use thermode_platform::to_clock_resolution;

use super::{read_csv, ExportError};

/// The trial curves' loop-time column.
pub const LOOP_TIME_COLUMN: &str = "loop_time_s";
/// A recording whose loop-time zero is within this of the session's comes from the same daemon, whose loop clock
/// it shares exactly \[s\]: 1 (a daemon's zero is its start; the session's estimate of it is good to a round trip).
pub const SAME_DAEMON_S: f64 = 1.0;

/// A session's trial starts on the display's loop clock.
#[derive(Debug, Clone, PartialEq)]
pub struct SessionClock {
    /// Each trial's start (its curve's first sample) on the loop clock \[s\], in the order of the session CSV.
    trial_starts_s: Vec<f64>,
    /// The wall-clock time of loop time zero \[s since 1970\], from the session sidecar, if it names it.
    loop_zero_unix_s: Option<f64>,
}

impl SessionClock {
    /// The clock of the session whose CSV is `csv` (its `header` and `rows`) and sidecar `meta`: `None` unless
    /// every trial row names a curve file (`curve_file`, beside the CSV) with a `loop_time_s` column.
    pub fn of(csv: &Path, meta: &Value, header: &[String], rows: &[Vec<String>]) -> Result<Option<Self>, ExportError> {
        let Some(column) = header.iter().position(|h| h == "curve_file") else {
            return Ok(None);
        };
        let folder = csv.parent().unwrap_or(Path::new("."));
        let mut trial_starts_s = Vec::with_capacity(rows.len());
        for row in rows {
            let name = row.get(column).map_or("", |v| v.trim());
            let path = folder.join(name);
            if name.is_empty() || !path.is_file() {
                return Ok(None);
            }
            match first_loop_time_s(&path)? {
                Some(start_s) => trial_starts_s.push(start_s),
                None => return Ok(None),
            }
        }
        if trial_starts_s.is_empty() {
            return Ok(None);
        }
        let loop_zero_unix_s = meta
            .pointer("/device/loop_time_zero_unix_s")
            .and_then(Value::as_f64)
            .filter(|v| v.is_finite());
        Ok(Some(SessionClock {
            trial_starts_s,
            loop_zero_unix_s,
        }))
    }

    /// The session time of loop time `loop_s` \[s\]: seconds since the first trial's start, to the clock's
    /// nanosecond.
    pub fn session_time_s(&self, loop_s: f64) -> f64 {
        to_clock_resolution(loop_s - self.trial_starts_s[0])
    }

    /// The onset of trial row `index` \[s\] (`None` past the last row).
    pub fn onset_s(&self, index: usize) -> Option<f64> {
        self.trial_starts_s.get(index).map(|&t| self.session_time_s(t))
    }

    /// Seconds to add to the `time_s` of the recording `path` to put it on the session's loop clock: 0 when it
    /// comes from the same daemon (its `.clock.json` zero within [`SAME_DAEMON_S`] of the session's, or either zero
    /// unknown), else the difference of the two wall-clock zeros.
    pub fn recording_offset_s(&self, path: &Path) -> f64 {
        let recording_zero_unix_s = std::fs::read_to_string(path.with_extension("clock.json"))
            .ok()
            .and_then(|text| serde_json::from_str::<Value>(&text).ok())
            .and_then(|v| v.get("loop_time_zero_unix_s").and_then(Value::as_f64));
        match (recording_zero_unix_s, self.loop_zero_unix_s) {
            (Some(recording), Some(session)) if (recording - session).abs() > SAME_DAEMON_S => recording - session,
            _ => 0.0,
        }
    }
}

/// The first `loop_time_s` of the curve CSV `path`, if it has the column and a row.
fn first_loop_time_s(path: &Path) -> Result<Option<f64>, ExportError> {
    let (header, rows) = read_csv(path)?;
    let Some(column) = header.iter().position(|h| h == LOOP_TIME_COLUMN) else {
        return Ok(None);
    };
    Ok(rows
        .first()
        .and_then(|row| row.get(column))
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|v| v.is_finite()))
}
