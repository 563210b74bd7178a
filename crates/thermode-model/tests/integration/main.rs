//! The crate's integration tests in one binary (one link instead of one per file keeps the test build short).

mod fv_adaptive;
mod fv_depth;
mod fv_modal;
mod fv_physics;
mod fv_replace_object;
mod kron_physics;
mod peltier_physics;
mod ranges;
