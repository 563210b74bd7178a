//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

mod analysis;
mod display_stimulus;
mod kill;
mod participant_validation;
mod plan;
mod procedures;
mod runner;
