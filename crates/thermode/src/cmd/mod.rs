//! One module per subcommand; each exposes its clap `Args` struct and a `run` function.

pub mod bench;
pub mod calibrate;
pub mod demo;
pub mod dose;
pub mod emulate;
pub mod emulate_hw;
pub mod identify;
pub mod lab_analyze;
pub mod lab_export;
pub mod lab_plan;
pub mod lab_procedure;
pub mod lab_run;
pub mod materials;
pub mod render;
pub mod serve;
pub mod simulate;
pub mod tune;
