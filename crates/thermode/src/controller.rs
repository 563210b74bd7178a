//! The `--controller` choice, one type for every command that takes it: `render` runs `pid`, `model` or `both`;
//! a display in real time (`serve` and the commands sharing its display set-up, [`crate::display`]) and
//! `lab run` run `model` or `pid`. Each command lists the values it accepts with its own help text
//! ([`ControllerArg::parser`]).

use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};

/// The controller(s) a command runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerArg {
    /// The paper's PID with tuned gains.
    Pid,
    /// thermode's model-based controller (observer, Peltier feedforward).
    Model,
    /// Both, one after the other (`render` only).
    Both,
}

/// The values a display in real time accepts (`serve`, `demo`, `bench`), with their help text.
pub const DISPLAY_CONTROLLERS: [(ControllerArg, &str); 2] = [
    (ControllerArg::Model, MODEL_HELP),
    (
        ControllerArg::Pid,
        "The paper's PID with the tuned gains of the display",
    ),
];

/// The values `render` accepts, with their help text.
pub const RENDER_CONTROLLERS: [(ControllerArg, &str); 3] = [
    (
        ControllerArg::Pid,
        "The paper's PID on the low-pass filtered sensor (tuned gains)",
    ),
    (ControllerArg::Model, MODEL_HELP),
    (
        ControllerArg::Both,
        "Both, one after the other (one panel each in the plot)",
    ),
];

/// The values `lab run` accepts, with their help text.
pub const LAB_CONTROLLERS: [(ControllerArg, &str); 2] = [
    (ControllerArg::Model, MODEL_HELP),
    (
        ControllerArg::Pid,
        "The paper's PID (the tuned gains of the shipped display that matches the device)",
    ),
];

/// The help text of `model`, the same in every command.
const MODEL_HELP: &str = "thermode's model-based controller (observer, Peltier feedforward)";

impl ControllerArg {
    /// The value's spelling on the command line.
    pub fn name(self) -> &'static str {
        match self {
            ControllerArg::Pid => "pid",
            ControllerArg::Model => "model",
            ControllerArg::Both => "both",
        }
    }

    /// The value with the spelling `name`, if any.
    pub fn from_name(name: &str) -> Option<Self> {
        [ControllerArg::Pid, ControllerArg::Model, ControllerArg::Both]
            .into_iter()
            .find(|c| c.name() == name)
    }

    /// The clap parser of a command that accepts the values of `choices` (in that order, each with its help
    /// text): any other value is refused with the list of these.
    pub fn parser(choices: &'static [(ControllerArg, &'static str)]) -> impl TypedValueParser<Value = ControllerArg> {
        PossibleValuesParser::new(
            choices
                .iter()
                .map(|&(controller, help)| PossibleValue::new(controller.name()).help(help)),
        )
        .try_map(|name| ControllerArg::from_name(&name).ok_or_else(|| format!("unknown controller {name:?}")))
    }
}
