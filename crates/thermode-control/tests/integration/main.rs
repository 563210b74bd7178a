//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

mod envelope_props;
mod model_controller;
mod pid_plant;
