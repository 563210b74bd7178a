//! Helpers shared by the runtime's integration tests: a spy device around the simulated display (records every
//! applied current and the true plate temperature; faults and failing reads can be injected from the test), daemon
//! start-up with the render pipeline or the tracking engine, a tiny HTTP client, a WebSocket client, and bounded
//! waiting.

#![allow(dead_code)]

use std::io::{BufRead, Read, Write};
use std::net::{SocketAddr, TcpStream};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use serde_json::Value;
use thermode_device::{
    DefaultFinger, Device, DeviceConfig, DeviceCut, DeviceError, Fault, Measures, Reading, SimulatedDisplay,
};
use thermode_pipeline::{gains_for_device, ControllerKind, PipelineConfig};
use thermode_platform::{Clock, MonotonicClock};
use thermode_runtime::engine::{pipeline_engines, tracking_engines};
use thermode_runtime::EngineFactory;
use thermode_safety::DriveCommand;
use thermode_serve::{Daemon, DaemonConfig, ServerConfig};
use tokio::net::TcpStream as TokioTcpStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::{MaybeTlsStream, WebSocketStream};

/// One applied command.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Applied {
    /// Device time \[s\].
    pub time_s: f64,
    /// Channel.
    pub channel: usize,
    /// Current \[A\].
    pub current_a: f64,
}

/// What the spy saw.
#[derive(Debug, Default)]
pub struct SpyLog {
    /// Every applied command.
    pub applied: Vec<Applied>,
    /// Highest true plate temperature of any channel \[°C\].
    pub max_plate_c: f64,
    /// Lowest true plate temperature of any channel \[°C\].
    pub min_plate_c: f64,
    /// Largest |current| applied \[A\].
    pub max_abs_current_a: f64,
    /// Channel 0's true plate after every poll: (device time \[s\], plate \[°C\]).
    pub plate_trace: Vec<(f64, f64)>,
    /// The outage of [`SpyControl::outage_when_hot`] once it is scheduled: (from, until) \[s, device time\].
    pub outage_s: Option<(f64, f64)>,
}

/// What the test asks the spy to do at the next step.
#[derive(Debug, Default)]
pub struct SpyControl {
    /// Faults to inject.
    pub inject: Vec<(usize, Fault)>,
    /// Channels whose faults to clear.
    pub clear: Vec<usize>,
    /// Channels whose reads fail.
    pub failing_reads: Vec<usize>,
    /// Channels whose reads say the device's own protection cut them.
    pub cut_reads: Vec<(usize, DeviceCut)>,
    /// Reads of channel 0 fail for a while once its true plate first reaches a temperature, in device time (so a
    /// test on a jumping clock gets it at the right moment): (plate \[°C\], delay after that \[s\], length \[s\]).
    pub outage_when_hot: Option<(f64, f64, f64)>,
    /// The outage of [`SpyControl::outage_when_hot`] is the device's own cut (over-temperature, heating off, its
    /// readings still reported) instead of failing reads.
    pub outage_is_cut: bool,
}

/// The simulated display with a recorder and a remote control.
pub struct SpyDevice {
    inner: SimulatedDisplay<DefaultFinger>,
    time_s: f64,
    /// What the spy says it measures (default: everything).
    pub measures: Measures,
    pub log: Arc<Mutex<SpyLog>>,
    pub control: Arc<Mutex<SpyControl>>,
}

impl SpyDevice {
    pub fn new(channels: usize) -> SpyDevice {
        let inner = SimulatedDisplay::fingertips(&DeviceConfig::default(), channels, 7).expect("simulated display");
        let log = SpyLog {
            min_plate_c: f64::INFINITY,
            max_plate_c: f64::NEG_INFINITY,
            ..SpyLog::default()
        };
        SpyDevice {
            inner,
            time_s: 0.0,
            measures: Measures::ALL,
            log: Arc::new(Mutex::new(log)),
            control: Arc::new(Mutex::new(SpyControl::default())),
        }
    }
}

impl Device for SpyDevice {
    fn channel_count(&self) -> usize {
        self.inner.channel_count()
    }

    fn measures(&self) -> Measures {
        self.measures
    }

    fn apply(&mut self, channel: usize, command: &DriveCommand) -> Result<(), DeviceError> {
        let mut log = self.log.lock().expect("spy log");
        log.applied.push(Applied {
            time_s: self.time_s,
            channel,
            current_a: command.current_a(),
        });
        log.max_abs_current_a = log.max_abs_current_a.max(command.current_a().abs());
        drop(log);
        self.inner.apply(channel, command)
    }

    fn read(&mut self, channel: usize) -> Result<Reading, DeviceError> {
        let control = self.control.lock().expect("spy control");
        if control.failing_reads.contains(&channel) {
            let fault = thermode_device::LinkFault::ReadFailed {
                error: std::io::ErrorKind::Other.into(),
            };
            return Err(DeviceError::Link(thermode_device::LinkError::device("spy", fault)));
        }
        let outage_is_cut = control.outage_is_cut;
        if let Some(&(_, cut)) = control.cut_reads.iter().find(|(c, _)| *c == channel) {
            // A real device goes on reporting its plate while cut.
            return Err(DeviceError::Cut {
                channel,
                cut,
                reading: self.inner.read(channel).ok(),
            });
        }
        drop(control);
        let outage = self.log.lock().expect("spy log").outage_s;
        if channel == 0 && outage.is_some_and(|(from_s, until_s)| (from_s..until_s).contains(&self.time_s)) {
            if outage_is_cut {
                // The device cut its own drive: the loop sends 0 A, the plate is still reported.
                return Err(DeviceError::Cut {
                    channel,
                    cut: DeviceCut::OverTemperature,
                    reading: self.inner.read(channel).ok(),
                });
            }
            let fault = thermode_device::LinkFault::ReadFailed {
                error: std::io::ErrorKind::TimedOut.into(),
            };
            return Err(DeviceError::Link(thermode_device::LinkError::device("spy", fault)));
        }
        self.inner.read(channel)
    }

    fn poll(&mut self, now_s: f64) {
        {
            let mut control = self.control.lock().expect("spy control");
            for (channel, fault) in control.inject.drain(..) {
                self.inner
                    .channel_mut(channel)
                    .expect("channel")
                    .inject(fault)
                    .expect("fault");
            }
            for channel in control.clear.drain(..) {
                self.inner.channel_mut(channel).expect("channel").clear_faults();
            }
        }
        self.inner.poll(now_s);
        self.time_s = self.inner.time_s();
        let mut log = self.log.lock().expect("spy log");
        let plate_0_c = self.inner.channel(0).expect("channel 0").state().plate_c;
        log.plate_trace.push((self.time_s, plate_0_c));
        let when_hot = self.control.lock().expect("spy control").outage_when_hot;
        if let Some((hot_c, delay_s, length_s)) = when_hot.filter(|_| log.outage_s.is_none()) {
            if plate_0_c >= hot_c {
                log.outage_s = Some((self.time_s + delay_s, self.time_s + delay_s + length_s));
            }
        }
        for channel in 0..self.inner.channel_count() {
            let plate_c = self.inner.channel(channel).expect("channel").state().plate_c;
            log.max_plate_c = log.max_plate_c.max(plate_c);
            log.min_plate_c = log.min_plate_c.min(plate_c);
        }
    }
}

/// The pipelines `thermode serve` runs by default: the default display, the model controller.
pub fn pipelines() -> EngineFactory {
    pipeline_engines(PipelineConfig::new(DeviceConfig::default(), ControllerKind::Model))
}

/// PID pipelines with the tuned gains of the default display.
pub fn pid_pipelines() -> EngineFactory {
    let (gains, _) = gains_for_device(&DeviceConfig::default()).expect("gains");
    pipeline_engines(PipelineConfig::new(DeviceConfig::default(), ControllerKind::Pid(gains)))
}

/// Simple tracking engines (fast).
pub fn trackers() -> EngineFactory {
    tracking_engines(32.0, 0.5, DeviceConfig::default().drive.current_limit_a)
}

/// A config on a free port, OSC on a free port, everything else default.
pub fn test_config() -> DaemonConfig {
    DaemonConfig {
        server: ServerConfig {
            port: 0,
            osc_port: Some(0),
            ..ServerConfig::default()
        },
        device_label: "sim".into(),
        ..DaemonConfig::default()
    }
}

/// A daemon on the real clock.
pub fn start(config: DaemonConfig, device: SpyDevice, engines: EngineFactory) -> Daemon {
    let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
    Daemon::start(config, Box::new(device), engines, clock).expect("daemon starts")
}

/// Polls `condition` every 5 ms for at most `limit_s` of real time.
pub fn wait_until(limit_s: f64, mut condition: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < limit_s {
        if condition() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    condition()
}

/// An HTTP/1.1 GET: (status code, body). `headers` are extra header lines.
pub fn http_get(addr: SocketAddr, path: &str, headers: &[(&str, &str)]) -> (u16, String) {
    http_request(addr, "GET", path, headers, None)
}

/// An HTTP/1.1 POST of `body`: (status code, body). `headers` are extra header lines.
pub fn http_post(addr: SocketAddr, path: &str, headers: &[(&str, &str)], body: &[u8]) -> (u16, String) {
    http_request(addr, "POST", path, headers, Some(body))
}

/// An HTTP/1.1 request with `method` and an optional `body` (sent with its `Content-Length`): (status code, body).
pub fn http_request(
    addr: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: Option<&[u8]>,
) -> (u16, String) {
    let mut stream = TcpStream::connect(addr).expect("connect");
    stream.set_read_timeout(Some(Duration::from_secs(10))).expect("timeout");
    let mut request = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
        request.push_str(&format!("Host: {addr}\r\n"));
    }
    for (k, v) in headers {
        request.push_str(&format!("{k}: {v}\r\n"));
    }
    if let Some(body) = body {
        request.push_str(&format!("Content-Length: {}\r\n", body.len()));
    }
    request.push_str("\r\n");
    let mut bytes = request.into_bytes();
    bytes.extend_from_slice(body.unwrap_or_default());
    // A server may answer (413) and close before reading a large body: a failed write is not the test's failure.
    let _ = stream.write_all(&bytes);
    let mut reader = std::io::BufReader::new(stream);
    let mut head = String::new();
    let mut content_length = None;
    loop {
        let mut line = String::new();
        if reader.read_line(&mut line).expect("read header") == 0 || line == "\r\n" {
            break;
        }
        if let Some((name, value)) = line.split_once(':') {
            if name.eq_ignore_ascii_case("content-length") {
                content_length = value.trim().parse::<usize>().ok();
            }
        }
        head.push_str(&line);
    }
    let mut body = Vec::new();
    match content_length {
        Some(n) => {
            body.resize(n, 0);
            reader.read_exact(&mut body).expect("read body");
        }
        None => {
            reader.read_to_end(&mut body).expect("read body");
        }
    }
    let status = head.split(' ').nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    (status, String::from_utf8_lossy(&body).into_owned())
}

/// GET returning JSON (panics on a non-200 status, printing the body).
pub fn get_json(addr: SocketAddr, path: &str) -> Value {
    let (status, body) = http_get(addr, path, &[]);
    assert_eq!(status, 200, "GET {path}: {body}");
    serde_json::from_str(&body).unwrap_or_else(|e| panic!("GET {path}: {e}: {body}"))
}

/// The client side of a WebSocket.
pub type Ws = WebSocketStream<MaybeTlsStream<TokioTcpStream>>;

/// Connects to `/api/ws` (with `?query` if given).
pub async fn ws_connect(addr: SocketAddr, query: &str) -> Ws {
    let url = format!("ws://{addr}/api/ws{query}");
    let (ws, _) = tokio_tungstenite::connect_async(url.as_str())
        .await
        .expect("ws connect");
    ws
}

/// The next JSON text message (bounded wait of 10 s; panics on anything else).
pub async fn next_json(ws: &mut Ws) -> Value {
    loop {
        let item = tokio::time::timeout(Duration::from_secs(10), ws.next())
            .await
            .expect("a message within 10 s")
            .expect("connection open")
            .expect("no protocol error");
        match item {
            Message::Text(text) => return serde_json::from_str(text.as_str()).expect("JSON"),
            Message::Ping(_) | Message::Pong(_) => continue,
            other => panic!("unexpected message {other:?}"),
        }
    }
}

/// Sends `text` and returns the reply with the same id (telemetry in between is skipped).
pub async fn ask(ws: &mut Ws, text: &str) -> Value {
    let sent: Value = serde_json::from_str(text).unwrap_or(Value::Null);
    let id = sent.get("id").cloned().unwrap_or(Value::Null);
    ws.send(Message::Text(text.to_string().into())).await.expect("send");
    for _ in 0..10_000 {
        let reply = next_json(ws).await;
        if reply["type"] != "telemetry" && reply["id"] == id {
            return reply;
        }
    }
    panic!("no reply to {text}");
}

/// A current-thread tokio runtime for the test's client side.
pub fn client_runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("tokio runtime")
}

/// What a channel shows, from its status or telemetry object: the material's name while touching, else the mode
/// (`air`, `direct`).
pub fn shows(c: &Value) -> String {
    let key = if c["mode"] == "touch" { "material" } else { "mode" };
    c[key].as_str().unwrap_or("?").to_string()
}

/// The status channel entry `i`.
pub fn channel(status: &Value, i: usize) -> &Value {
    &status["channels"][i]
}
