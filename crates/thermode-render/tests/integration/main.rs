//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

#[path = "../common/mod.rs"]
mod common;

mod dose;
mod faults;
mod identify;
mod judged;
mod kron_depth;
mod lying_sensor;
mod pipeline;
mod props;
mod run;
mod self_test;
mod true_plate;
mod truth;
