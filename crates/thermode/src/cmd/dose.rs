//! `thermode dose show` and `thermode dose reset`: the thermal-dose ledger that `thermode serve` keeps per channel
//! in its state directory, so that the dose survives restarts (`thermode_runtime::ledger`). Also where the state
//! directory is when `--state-dir` is not given ([`state_dir`]).
//!
//! Only `dose reset` lowers a channel's dose, and every reset is appended to the state directory's
//! `dose-reset.log` (UTC time, channel, the dose cleared, the reason) before the ledger changes; it is refused while
//! a daemon holds the state directory.

use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use clap::{Args, ValueEnum};
use thermode_runtime::ledger::{read_ledger, StateDir, LEDGER_FILE, RESET_LOG_FILE};

use crate::output::print_stdout;

/// Format of `dose show`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum FormatArg {
    /// Aligned text.
    Text,
    /// The ledger file's JSON.
    Json,
}

/// Arguments of `thermode dose show`.
#[derive(Args, Debug)]
pub struct ShowArgs {
    /// State directory of the ledger [default: $XDG_STATE_HOME/thermode, else ~/.local/state/thermode].
    #[arg(long = "state-dir", value_name = "DIR")]
    state_dir: Option<PathBuf>,
    /// Output format.
    #[arg(long, value_enum, default_value = "text")]
    format: FormatArg,
}

/// Arguments of `thermode dose reset`.
#[derive(Args, Debug)]
#[command(group = clap::ArgGroup::new("which").required(true).args(["channel", "all"]))]
pub struct ResetArgs {
    /// The channel (from 0) whose dose to clear.
    #[arg(long, value_name = "N")]
    channel: Option<usize>,
    /// Clear every channel; also sets a corrupt ledger aside (kept beside it) so that `serve` can start again.
    #[arg(long)]
    all: bool,
    /// Why (logged with the UTC time; e.g. "new participant P07").
    #[arg(long, value_name = "TEXT")]
    reason: String,
    /// State directory of the ledger [default: $XDG_STATE_HOME/thermode, else ~/.local/state/thermode].
    #[arg(long = "state-dir", value_name = "DIR")]
    state_dir: Option<PathBuf>,
}

/// The state directory: `given`, else `$XDG_STATE_HOME/thermode` (if set to an absolute path, as the XDG base
/// directory specification asks), else `$HOME/.local/state/thermode`; an error if none is known.
pub fn state_dir(given: Option<&Path>) -> Result<PathBuf> {
    let env = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    state_dir_from(given, env("XDG_STATE_HOME"), env("HOME"))
}

fn state_dir_from(given: Option<&Path>, xdg_state_home: Option<PathBuf>, home: Option<PathBuf>) -> Result<PathBuf> {
    if let Some(dir) = given {
        return Ok(dir.to_path_buf());
    }
    if let Some(xdg) = xdg_state_home.filter(|p| p.is_absolute()) {
        return Ok(xdg.join("thermode"));
    }
    if let Some(home) = home {
        return Ok(home.join(".local").join("state").join("thermode"));
    }
    bail!("no state directory: neither XDG_STATE_HOME nor HOME is set; give --state-dir DIR")
}

/// Runs `thermode dose show`.
pub fn show(args: &ShowArgs) -> Result<()> {
    let dir = state_dir(args.state_dir.as_deref())?;
    let ledger = read_ledger(&dir)?;
    let text = match args.format {
        FormatArg::Json => ledger.to_json(),
        FormatArg::Text => {
            let mut text = format!("dose ledger {}\n", dir.join(LEDGER_FILE).display());
            if ledger.is_empty() {
                text.push_str("no dose recorded\n");
            } else {
                text.push_str("channel   cem43_min  time_at_or_above_43_s  lockout  updated (UTC)\n");
                for (channel, e) in ledger.entries() {
                    text.push_str(&format!(
                        "{channel:>7}  {:>10.6}  {:>21.2}  {:>7}  {}\n",
                        e.dose.cem43_min,
                        e.dose.time_at_or_above_43_s,
                        if e.dose.lockout { "yes" } else { "no" },
                        e.updated_utc
                    ));
                }
            }
            text
        }
    };
    print_stdout(&text)
}

/// Runs `thermode dose reset`.
pub fn reset(args: &ResetArgs) -> Result<()> {
    let dir = state_dir(args.state_dir.as_deref())?;
    let state = StateDir::open(&dir)?;
    let lines = match args.channel {
        Some(channel) if !args.all => vec![state.reset_channel(channel, &args.reason)?],
        _ => state.reset_all(&args.reason)?,
    };
    let mut text = lines.join("\n");
    text.push_str(&format!("\nlogged in {}\n", dir.join(RESET_LOG_FILE).display()));
    print_stdout(&text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_state_directory_follows_xdg_then_home() {
        let dir = |given: Option<&str>, xdg: Option<&str>, home: Option<&str>| {
            state_dir_from(given.map(Path::new), xdg.map(PathBuf::from), home.map(PathBuf::from))
                .map(|p| p.display().to_string())
                .map_err(|e| e.to_string())
        };
        assert_eq!(dir(Some("/s"), Some("/x"), Some("/h")), Ok("/s".into()));
        assert_eq!(dir(None, Some("/x"), Some("/h")), Ok("/x/thermode".into()));
        assert_eq!(
            dir(None, Some("relative"), Some("/h")),
            Ok("/h/.local/state/thermode".into())
        );
        assert_eq!(dir(None, None, Some("/h")), Ok("/h/.local/state/thermode".into()));
        assert!(dir(None, None, None).is_err_and(|e| e.contains("--state-dir")));
    }
}
