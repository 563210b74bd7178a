//! Telemetry history for `GET /api/history`: a task on the network runtime samples the loop's published snapshot
//! [`HISTORY_RATE_HZ`] times a second into a ring buffer of the last [`HISTORY_WINDOW_S`] seconds, so a page that
//! opens late can back-fill its plots. The control loop takes no part: it publishes its snapshot as before, with
//! no allocation and no extra lock on the loop thread.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use thermode_protocol::reply::{self, ChannelHistory};

use thermode_runtime::snapshot::{Shared, Snapshot};

/// Samples kept per second \[Hz\].
pub const HISTORY_RATE_HZ: f64 = 10.0;
/// Seconds of history kept \[s\].
pub const HISTORY_WINDOW_S: f64 = 60.0;

/// One channel at one sample: target skin, rendered skin, display sensor, display set-point \[°C\], drive \[A\].
type Row = [f64; 5];

/// The ring buffer: (loop time \[s\], one row per channel), oldest first.
#[derive(Debug, Default)]
pub struct History {
    samples: Mutex<VecDeque<(f64, Vec<Row>)>>,
}

impl History {
    /// Appends the snapshot's tick unless it is already the newest, dropping samples older than the window.
    pub fn push(&self, snapshot: &Snapshot) {
        let mut samples = self.samples.lock().unwrap_or_else(|e| e.into_inner());
        if samples.back().is_some_and(|(t, _)| *t >= snapshot.time_s) {
            return;
        }
        let rows = snapshot
            .channels
            .iter()
            .map(|c| {
                let t = &c.telemetry;
                [t.target_skin_c, t.skin_c, t.sensor_c, t.display_setpoint_c, t.current_a]
            })
            .collect();
        samples.push_back((snapshot.time_s, rows));
        while samples
            .front()
            .is_some_and(|(t, _)| *t < snapshot.time_s - HISTORY_WINDOW_S)
        {
            samples.pop_front();
        }
    }

    /// The `/api/history` body: per channel, parallel arrays over the kept samples (null where not finite).
    pub fn to_history(&self) -> reply::History {
        let samples = self.samples.lock().unwrap_or_else(|e| e.into_inner());
        let time_s: Vec<f64> = samples.iter().map(|(t, _)| *t).collect();
        let count = samples.back().map_or(0, |(_, rows)| rows.len());
        let column = |i: usize, k: usize| -> Vec<Option<f64>> {
            samples
                .iter()
                .map(|(_, rows)| rows.get(i).map(|r| r[k]).filter(|v| v.is_finite()))
                .collect()
        };
        let channels = (0..count).map(|i| ChannelHistory {
            channel: i,
            target_skin_c: column(i, 0),
            skin_c: column(i, 1),
            sensor_c: column(i, 2),
            display_setpoint_c: column(i, 3),
            current_a: column(i, 4),
        });
        reply::History {
            rate_hz: HISTORY_RATE_HZ,
            window_s: HISTORY_WINDOW_S,
            time_s,
            channels: channels.collect(),
        }
    }
}

/// Samples the published snapshot into `history` until the runtime stops.
pub async fn sample(shared: Arc<Shared>, history: Arc<History>) {
    let mut every = tokio::time::interval(Duration::from_secs_f64(1.0 / HISTORY_RATE_HZ));
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        every.tick().await;
        history.push(&shared.snapshot());
    }
}
