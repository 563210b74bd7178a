//! thermode-platform: what thermode takes from the machine it runs on, in one place.
//!
//! - [`time`]: the one [`Clock`] trait with [`MonotonicClock`] (real time) and [`ManualClock`] (tests: time moves
//!   only when told to, or jumps to every deadline it is asked to sleep until), the drift-free fixed-rate
//!   [`Ticker`], and the civil (UTC calendar) date and time of day.
//! - [`rt`]: real-time scheduling (`SCHED_FIFO`) and locked memory for the control loop, where the system grants
//!   them, and the open-files limit.
//! - [`fs`]: the one atomic file writer: a temporary file beside the target, synced, renamed over it, and the
//!   folder synced; a target that is not a regular file (a device, a FIFO) is written in place, never replaced.
//!
//! The link to a display, the daemon's control loop and the lab's trial runner all take their time from a
//! `&dyn Clock`, so a recorded run can be replayed on a [`ManualClock`] bit for bit.

pub mod csv_text;
pub mod fs;
pub mod rt;
pub mod time;

pub use fs::{write_atomically, write_bytes_atomically, WriteError, WritingAhead, WRITE_AHEAD_BYTES};
pub use time::{
    civil_date, civil_from_days, days_from_civil, parse_iso_date, to_clock_resolution, utc_iso8601, utc_iso8601_ms,
    utc_stamp, Clock, ManualClock, MonotonicClock, Tick, Ticker, TickerError, CLOCK_RESOLUTION_S,
};
