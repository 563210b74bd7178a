//! A program's events (a segment's start, a response, the program's end) as the wire tells them
//! ([`ProgramEvent`]), read from the loop's tick records: sent to every WebSocket telemetry subscriber by the
//! thread [`start`] runs, and pushed to the LSL marker stream under `serve --lsl` (`crate::lsl`).

use std::sync::mpsc::{sync_channel, SyncSender};
use std::sync::Arc;

use thermode_protocol::{finite, ProgramEvent, ProgramEventKind, Response};
use thermode_runtime::snapshot::{RecordRow, TickRecord};
use tokio::sync::broadcast;

/// Tick records the event thread may fall behind by \[ticks\] (1 s at 1 kHz); further ones are dropped and counted
/// by the loop.
pub const EVENT_QUEUE_TICKS: usize = 1024;
/// Events a slow WebSocket client may fall behind by before it misses some.
pub const EVENT_BACKLOG: usize = 4096;

/// Every program event of one tick, channel by channel: a response first, then a segment's start, then the end.
pub fn of_record(record: &TickRecord) -> Vec<ProgramEvent> {
    let mut events = Vec::new();
    for (channel, row) in record.channels().iter().enumerate() {
        if row.program.has_event() {
            events.extend(of_row(channel, row, record.tick, record.time_s));
        }
    }
    events
}

/// The program events of one channel's row.
fn of_row(channel: usize, row: &RecordRow, tick: u64, time_s: f64) -> Vec<ProgramEvent> {
    let mark = &row.program;
    let t = &row.telemetry;
    let event = |event| ProgramEvent {
        event,
        channel,
        tick,
        time_s,
        segment: None,
        to_c: None,
        cutoff_c: None,
        kind: None,
        value: None,
        setpoint_c: finite(t.display_setpoint_c),
        sensor_c: finite(t.sensor_c),
    };
    let mut events = Vec::new();
    if let Some((kind, value, ended)) = mark.response {
        events.push(ProgramEvent {
            kind: Some(kind),
            value,
            segment: ended,
            ..event(ProgramEventKind::Response)
        });
    }
    if let Some((segment, to_c, cutoff_c)) = mark.started {
        events.push(ProgramEvent {
            segment: Some(segment),
            to_c,
            cutoff_c,
            ..event(ProgramEventKind::SegmentStart)
        });
    }
    if mark.ended {
        events.push(event(ProgramEventKind::ProgramEnd));
    }
    events
}

/// Starts the thread that reads tick records and broadcasts their program events as WebSocket messages: the feed
/// to give the loop, and the sender every connection subscribes to. The thread ends when the loop drops the feed.
pub fn start() -> Result<(SyncSender<TickRecord>, broadcast::Sender<Arc<str>>), std::io::Error> {
    let (feed, records) = sync_channel::<TickRecord>(EVENT_QUEUE_TICKS);
    let (sender, _) = broadcast::channel::<Arc<str>>(EVENT_BACKLOG);
    let broadcaster = sender.clone();
    std::thread::Builder::new()
        .name("thermode-events".into())
        .spawn(move || {
            while let Ok(record) = records.recv() {
                for event in of_record(&record) {
                    // No receiver (nobody connected) is not an error.
                    let _ = broadcaster.send(Arc::from(Response::ProgramEvent(event).to_text()));
                }
            }
        })?;
    Ok((feed, sender))
}
