//! `thermode bench`: control-loop jitter at a given rate and channel count (default 1 kHz, 10 channels of the full
//! render pipeline on the simulated display) and the latency from a WebSocket `touch` to the drive command, in loop
//! periods (or, with `--flooders`, a fresh client's `stop_all` under a program flood, in ms). Prints figures;
//! asserts nothing. Build with `--release` for meaningful numbers.

use std::sync::Arc;

use anyhow::Result;
use clap::{Args, ValueEnum};
use thermode_platform::{Clock, MonotonicClock};
use thermode_serve::bench::{self, BenchConfig};

use crate::display::{build_display, DisplayArgs};
use crate::output::print_stdout;

/// Output format of `thermode bench`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum BenchFormat {
    /// Human-readable lines.
    Text,
    /// One JSON object.
    Json,
}

/// Arguments of `thermode bench`.
#[derive(Args, Debug, Clone)]
pub struct BenchArgs {
    #[command(flatten)]
    pub display: DisplayArgs,
    /// Control-loop rate [Hz].
    #[arg(long, value_name = "HZ", default_value_t = 1000.0)]
    pub rate: f64,
    /// Length of the measured run [s].
    #[arg(long, value_name = "S", default_value_t = 10.0)]
    pub duration: f64,
    /// Output format.
    #[arg(long, value_enum, default_value = "text")]
    pub format: BenchFormat,
    /// WebSocket clients subscribed to telemetry at 100 Hz during the run.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub subscribers: usize,
    /// WebSocket clients flooding the daemon with 999-segment programs on every channel, sent back to back; with
    /// any, a fresh client's `stop_all` is timed (every 0.5 s) instead of the touches.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub flooders: usize,
    /// Ask for real-time scheduling (SCHED_FIFO) of the loop and locked memory, as `serve` does by default.
    #[arg(long)]
    pub realtime: bool,
    /// Measure the machine's timer floor instead: a thread that only sleeps to the same deadlines (same rate,
    /// duration and real-time request) and does nothing else. What it misses, no loop on this machine can meet.
    #[arg(long)]
    pub floor: bool,
}

/// Runs `thermode bench`.
pub fn run(args: &BenchArgs) -> Result<()> {
    if args.floor {
        eprintln!("bench: the timer floor at {} Hz for {} s …", args.rate, args.duration);
        let report = bench::timer_floor(args.rate, args.duration, args.realtime)?;
        return print_report(&report, args.format);
    }
    let mut display_args = args.display.clone();
    if display_args.is_sim() {
        // The simulated display at its largest; a real display has the channels it reports.
        display_args.channels = Some(display_args.channels.unwrap_or(10));
    }
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    // The identified device files are looked for where `serve` keeps them by default (no state directory: nowhere).
    let state_dir = super::dose::state_dir(None).ok();
    let display = build_display(&display_args, &clock, state_dir.as_deref())?;
    for line in &display.notices {
        eprintln!("thermode: {line}");
    }
    eprintln!(
        "bench: {} at {} Hz for {} s …",
        display.description, args.rate, args.duration
    );
    let config = BenchConfig {
        rate_hz: args.rate,
        duration_s: args.duration,
        subscribers: args.subscribers,
        flooders: args.flooders,
        realtime: args.realtime,
        ..BenchConfig::default()
    };
    let report = bench::run(&config, display.device, display.engines)?;
    print_report(&report, args.format)
}

fn print_report<R: std::fmt::Display + serde::Serialize>(report: &R, format: BenchFormat) -> Result<()> {
    let text = match format {
        BenchFormat::Text => format!("{report}\n"),
        BenchFormat::Json => serde_json::to_string_pretty(report)? + "\n",
    };
    print_stdout(&text)
}
