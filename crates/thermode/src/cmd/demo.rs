//! `thermode demo`: `thermode serve` plus a short scripted sequence of touches (aluminium on the index finger, wood
//! on the middle finger, steel on the thumb, releases) repeated until the end, so a newcomer sees the dashboard move
//! without writing a client. `--duration S` makes it exit (for tests and CI); SIGINT and SIGTERM stop it cleanly, as
//! they stop `serve`.

use anyhow::Result;
use clap::Args;
use thermode_model::materials;
use thermode_runtime::{Command, CommandSender, Owner};

use super::serve::{self, ServeArgs};
use crate::signals::StopSignals;

/// Arguments of `thermode demo`: those of `thermode serve`.
#[derive(Args, Debug, Clone)]
pub struct DemoArgs {
    #[command(flatten)]
    pub serve: ServeArgs,
}

/// One step of the script: at `at_s` into the cycle, touch `material` on `finger` (or release it with `None`).
struct Step {
    at_s: f64,
    finger: usize,
    material: Option<&'static str>,
}

/// Length of one cycle of the script \[s\].
const CYCLE_S: f64 = 20.0;

const SCRIPT: [Step; 8] = [
    Step {
        at_s: 1.0,
        finger: 1,
        material: Some("aluminium"),
    },
    Step {
        at_s: 4.0,
        finger: 2,
        material: Some("wood"),
    },
    Step {
        at_s: 7.0,
        finger: 1,
        material: None,
    },
    Step {
        at_s: 8.0,
        finger: 0,
        material: Some("steel"),
    },
    Step {
        at_s: 11.0,
        finger: 2,
        material: None,
    },
    Step {
        at_s: 12.0,
        finger: 3,
        material: Some("rubber"),
    },
    Step {
        at_s: 15.0,
        finger: 0,
        material: None,
    },
    Step {
        at_s: 17.0,
        finger: 3,
        material: None,
    },
];

const FINGERS: [&str; 5] = ["thumb", "index finger", "middle finger", "ring finger", "little finger"];

/// Runs `thermode demo`.
pub fn run(args: &DemoArgs) -> Result<()> {
    let signals = StopSignals::install()?;
    let daemon = serve::start(&args.serve)?;
    let channels = daemon.snapshot().map_or(1, |s| s.channels.len());
    let commands = daemon.commands();
    println!("demo: a touch every few seconds; watch the dashboard");
    let mut next = 0usize;
    let ended = serve::run_for(args.serve.duration, &signals, |elapsed_s| {
        serve::print_notices(&daemon);
        let Some(commands) = &commands else {
            return;
        };
        while let Some(step) = due(next, elapsed_s) {
            play(commands, step, channels);
            next += 1;
        }
    })?;
    serve::finish(daemon, ended)
}

/// The step with running number `n` if it is due at `elapsed_s`.
fn due(n: usize, elapsed_s: f64) -> Option<&'static Step> {
    let step = &SCRIPT[n % SCRIPT.len()];
    let at_s = (n / SCRIPT.len()) as f64 * CYCLE_S + step.at_s;
    (elapsed_s >= at_s).then_some(step)
}

fn play(commands: &CommandSender, step: &Step, channels: usize) {
    let channel = step.finger.min(channels - 1);
    let finger = if channels == 5 {
        FINGERS[channel].to_string()
    } else {
        format!("channel {channel}")
    };
    let command = match step.material.map(materials::find) {
        Some(Ok(material)) => {
            println!("demo: {finger} touches {}", material.name);
            Command::touch(channel, material, 23.0, Owner::Script)
        }
        Some(Err(e)) => {
            eprintln!("demo: {e}");
            return;
        }
        None => {
            println!("demo: {finger} lets go");
            Command::Release { channel }
        }
    };
    if let Err(e) = commands.send(command) {
        eprintln!("demo: {e}");
    }
}
