//! One module per subcommand; each exposes its clap `Args` struct and a `run` function.

pub mod lab_analyze;
pub mod materials;
pub mod simulate;
