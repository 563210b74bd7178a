//! `thermode lab export --bids DIR`: the lab's sessions (and `serve --record` recordings assigned to participants)
//! as a BIDS data set; see `thermode_lab::export` for what is written and how.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use clap::Args;
use thermode_lab::export::{export_bids, BidsOptions};

/// Arguments of `thermode lab export`.
#[derive(Args, Debug)]
pub struct LabExportArgs {
    /// Write a BIDS data set into this folder (created; must be new or empty).
    #[arg(long, value_name = "DIR")]
    bids: PathBuf,
    /// The lab's data folder (session CSVs and their JSON sidecars, as `lab run` writes them).
    #[arg(long, default_value = "data")]
    data_dir: PathBuf,
    /// A `serve --record` CSV and the participant it belongs to, as PARTICIPANT=FILE (added to that participant's
    /// first session as `_stim`/`_physio` signals); repeatable.
    #[arg(long, value_name = "PARTICIPANT=FILE")]
    recording: Vec<String>,
}

/// Runs `thermode lab export`.
pub fn run(args: &LabExportArgs) -> Result<()> {
    let recordings = args
        .recording
        .iter()
        .map(|given| parse_recording(given))
        .collect::<Result<Vec<_>>>()?;
    let options = BidsOptions {
        data_dir: args.data_dir.clone(),
        out_dir: args.bids.clone(),
        recordings,
    };
    let summary = export_bids(&options).with_context(|| format!("BIDS export to {}", args.bids.display()))?;
    println!(
        "wrote BIDS data set {}: {} subject(s), {} session(s), {} trial(s), {} continuous signal file(s)",
        args.bids.display(),
        summary.subjects,
        summary.sessions,
        summary.trials,
        summary.signals
    );
    Ok(())
}

fn parse_recording(given: &str) -> Result<(String, PathBuf)> {
    match given.split_once('=') {
        Some((participant, file)) if !participant.is_empty() && !file.is_empty() => {
            Ok((participant.to_string(), PathBuf::from(file)))
        }
        _ => bail!("--recording {given:?}: give PARTICIPANT=FILE"),
    }
}
