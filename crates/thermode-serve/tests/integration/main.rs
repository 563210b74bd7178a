//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

#[path = "../common/mod.rs"]
mod common;

mod api;
mod command;
mod dashboard;
mod dose;
mod example_client;
mod loop_core;
mod osc;
mod programs;
mod recording;
mod security;
mod serial;
mod service;
