//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

mod config;
mod device;
mod faults;
mod figures;
mod finger;
mod plant;
mod sensor;
