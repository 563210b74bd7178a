//! A program's events (a segment's start, a response, the program's end) as the wire tells them
//! ([`ProgramEvent`]), read from the loop's tick records by the thread [`start`] runs: sent to the WebSocket clients
//! that follow programs, and written beside a `--record` session as `<session>.events.csv` ([`EVENTS_CSV_HEADER`],
//! one row per event, flushed at once); pushed to the LSL marker stream under `serve --lsl` (`crate::lsl`).

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, SyncSender};
use std::sync::Arc;

use serde::Serialize;
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
        reason: None,
    };
    let mut events = Vec::new();
    if let Some((kind, value, ended)) = mark.response {
        events.push(ProgramEvent {
            kind: Some(crate::wire::response_kind(kind)),
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
    if let Some(stop) = mark.stopped {
        events.push(ProgramEvent {
            reason: Some(stop.to_string()),
            ..event(ProgramEventKind::ProgramStopped)
        });
    }
    events
}

/// The header of `<session>.events.csv`: loop time and tick, the channel, the event (`segment_start`, `response`,
/// `program_end`, `program_stopped`), the segment (started, or ended by the response), the started segment's target
/// and cut-off \[°C\], the response's kind and rating, the display set-point and the plate sensor of that tick
/// \[°C\] (empty where unknown), and why a program stopped (quoted).
pub const EVENTS_CSV_HEADER: &str =
    "time_s,tick,channel,event,segment,to_c,cutoff_c,kind,value,setpoint_c,sensor_c,reason";

/// The events file of the session recorded in `csv`: `<session>.events.csv` beside it.
pub fn events_csv_path(csv: &Path) -> PathBuf {
    csv.with_extension("events.csv")
}

/// Starts the thread that reads tick records, broadcasts their program events as WebSocket messages and, with a
/// recording, writes them to `events_csv` (created at the first event): the feed to give the loop, the sender every
/// connection subscribes to, and the thread (it ends once the loop has dropped the feed and its last events are
/// written: join it after stopping the loop). A write that fails is said once on
/// standard error and the file is not written again (the events still reach the clients).
pub fn start(events_csv: Option<PathBuf>) -> Result<EventThread, std::io::Error> {
    let (feed, records) = sync_channel::<TickRecord>(EVENT_QUEUE_TICKS);
    let (sender, _) = broadcast::channel::<Arc<str>>(EVENT_BACKLOG);
    let broadcaster = sender.clone();
    let thread = std::thread::Builder::new()
        .name("thermode-events".into())
        .spawn(move || {
            let mut file = events_csv.map(EventsFile::new);
            while let Ok(record) = records.recv() {
                let events = of_record(&record);
                if let (Some(writer), false) = (&mut file, events.is_empty()) {
                    writer.write(&events);
                }
                for event in events {
                    // No receiver (nobody connected) is not an error.
                    let _ = broadcaster.send(Arc::from(Response::ProgramEvent(event).to_text()));
                }
            }
        })?;
    Ok(EventThread { feed, sender, thread })
}

/// The running event thread: what [`start`] gives.
#[derive(Debug)]
pub struct EventThread {
    /// The loop's feed of tick records (give it to the loop among its feeds).
    pub feed: SyncSender<TickRecord>,
    /// The broadcast every WebSocket connection subscribes to.
    pub sender: broadcast::Sender<Arc<str>>,
    /// The thread, to join once the loop has stopped.
    pub thread: std::thread::JoinHandle<()>,
}

/// `<session>.events.csv`, opened at the first event.
struct EventsFile {
    path: PathBuf,
    out: Option<BufWriter<File>>,
    failed: bool,
}

impl EventsFile {
    fn new(path: PathBuf) -> Self {
        EventsFile {
            path,
            out: None,
            failed: false,
        }
    }

    /// Appends `events` and flushes; a failure is told once and ends the file's writing.
    fn write(&mut self, events: &[ProgramEvent]) {
        if self.failed {
            return;
        }
        if let Err(e) = self.try_write(events) {
            self.failed = true;
            eprintln!(
                "thermode serve: the program events file {} cannot be written ({e}); the events still reach the \
                 WebSocket clients and the LSL stream",
                self.path.display()
            );
        }
    }

    fn try_write(&mut self, events: &[ProgramEvent]) -> std::io::Result<()> {
        if self.out.is_none() {
            let mut out = BufWriter::new(File::create(&self.path)?);
            writeln!(out, "{EVENTS_CSV_HEADER}")?;
            self.out = Some(out);
        }
        let Some(out) = self.out.as_mut() else {
            return Ok(());
        };
        for event in events {
            writeln!(out, "{}", csv_row(event))?;
        }
        out.flush()
    }
}

/// A unit variant's name on the wire (`segment_start`, `button`).
fn wire_name(value: &impl Serialize) -> String {
    serde_json::to_value(value)
        .ok()
        .and_then(|v| v.as_str().map(str::to_string))
        .unwrap_or_default()
}

/// One event as a row of [`EVENTS_CSV_HEADER`].
fn csv_row(event: &ProgramEvent) -> String {
    let number = |v: Option<f64>| v.map_or(String::new(), |v| v.to_string());
    format!(
        "{:.6},{},{},{},{},{},{},{},{},{},{},{}",
        event.time_s,
        event.tick,
        event.channel,
        wire_name(&event.event),
        event.segment.map_or(String::new(), |s| s.to_string()),
        number(event.to_c),
        number(event.cutoff_c),
        event.kind.as_ref().map_or(String::new(), wire_name),
        number(event.value),
        number(event.setpoint_c),
        number(event.sensor_c),
        event
            .reason
            .as_ref()
            .map_or(String::new(), |r| format!("\"{}\"", r.replace('"', "\"\""))),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use thermode_runtime::command::ResponseKind;
    use thermode_runtime::snapshot::{Mode, ProgramMark, EMPTY_TELEMETRY};

    fn row(program: ProgramMark) -> RecordRow {
        RecordRow {
            label: Arc::from("program"),
            mode: Mode::Direct,
            object_c: None,
            material: None,
            direct: None,
            held_off: false,
            telemetry: thermode_runtime::Telemetry {
                display_setpoint_c: 29.5,
                sensor_c: 29.75,
                ..EMPTY_TELEMETRY
            },
            program,
        }
    }

    #[test]
    fn a_response_and_the_next_segment_on_one_tick_are_two_events_in_that_order() {
        let mark = ProgramMark {
            segment: Some(1),
            started: Some((1, Some(32.0), None)),
            ended: false,
            stopped: None,
            response: Some((ResponseKind::Rating, Some(55.0), Some(0))),
        };
        let events = of_row(3, &row(mark), 1200, 1.2);
        let kinds: Vec<ProgramEventKind> = events.iter().map(|e| e.event).collect();
        assert_eq!(kinds, [ProgramEventKind::Response, ProgramEventKind::SegmentStart]);
        assert_eq!(
            (events[0].segment, events[0].value),
            (Some(0), Some(55.0)),
            "the response ended segment 0"
        );
        assert_eq!((events[1].segment, events[1].to_c), (Some(1), Some(32.0)));
        assert!(events
            .iter()
            .all(|e| (e.channel, e.tick, e.sensor_c) == (3, 1200, Some(29.75))));
        assert_eq!(
            csv_row(&events[0]),
            "1.200000,1200,3,response,0,,,rating,55,29.5,29.75,"
        );
        assert_eq!(csv_row(&events[1]), "1.200000,1200,3,segment_start,1,32,,,,29.5,29.75,");
        assert_eq!(
            EVENTS_CSV_HEADER.split(',').count(),
            csv_row(&events[0]).split(',').count()
        );
        assert!(
            of_row(0, &row(ProgramMark::default()), 1, 0.01).is_empty(),
            "no event, no row"
        );
    }
}
