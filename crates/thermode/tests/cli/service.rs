//! `thermode serve` as an operator runs it, against the faults of the service it provides:
//! - the emulator stopped (SIGSTOP) and continued, then killed and restarted on the same `--link` path: the link
//!   comes back by itself, `clear_fault` succeeds and a set-point renders again, without restarting `serve`;
//! - `serve --token` does not listen for OSC: a UDP set-point changes nothing;
//! - `serve --record` on a 64 KiB tmpfs (a mount namespace of its own, `unshare`; skipped where that is not
//!   allowed): the status says `failed`, `rows_written` equals the rows in the file, the file ends with a newline,
//!   no channel is left rendering, the failure is on standard error, and SIGTERM then ends it with exit code 2 and
//!   a summary line that says the recording failed;
//! - `serve --state-dir` on a 64 KiB tmpfs that fills up mid-session: heating stops and new stimuli are refused until
//!   the ledger can be written again; the dose is on disk.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpStream, UdpSocket};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::Signal;
use serde_json::Value;

use super::serve_on_emulator::{binary, signal, status, Process, LIVENESS_S};

/// Polls `condition` every 50 ms for at most `limit_s`.
fn wait_until(limit_s: f64, mut condition: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed().as_secs_f64() < limit_s {
        if condition() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    condition()
}

/// Sends each request over one WebSocket and returns the reply with its id (answering pings, skipping the rest).
fn ws_ask(http_port: u16, requests: &[Value]) -> Vec<Value> {
    let mut s = TcpStream::connect(("127.0.0.1", http_port)).unwrap_or_else(|e| panic!("connect: {e}"));
    s.set_read_timeout(Some(Duration::from_secs(10)))
        .unwrap_or_else(|e| panic!("{e}"));
    write!(
        s,
        "GET /api/ws HTTP/1.1\r\nHost: 127.0.0.1:{http_port}\r\nConnection: Upgrade\r\nUpgrade: websocket\r\n\
         Sec-WebSocket-Version: 13\r\nSec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\n\r\n"
    )
    .unwrap_or_else(|e| panic!("handshake: {e}"));
    let mut head = Vec::new();
    let mut byte = [0u8; 1];
    while !head.ends_with(b"\r\n\r\n") {
        s.read_exact(&mut byte).unwrap_or_else(|e| panic!("101: {e}"));
        head.push(byte[0]);
    }
    assert!(head.starts_with(b"HTTP/1.1 101"), "{}", String::from_utf8_lossy(&head));
    let send = |s: &mut TcpStream, opcode: u8, payload: &[u8]| {
        let mask = [7u8, 1, 9, 3];
        let mut frame = vec![0x80 | opcode];
        if payload.len() < 126 {
            frame.push(0x80 | payload.len() as u8);
        } else {
            frame.push(0x80 | 126);
            frame.extend((payload.len() as u16).to_be_bytes());
        }
        frame.extend(mask);
        frame.extend(payload.iter().enumerate().map(|(i, b)| b ^ mask[i % 4]));
        s.write_all(&frame).unwrap_or_else(|e| panic!("send: {e}"));
    };
    let mut replies = Vec::new();
    for request in requests {
        send(&mut s, 1, request.to_string().as_bytes());
        loop {
            let mut h = [0u8; 2];
            s.read_exact(&mut h).unwrap_or_else(|e| panic!("frame: {e}"));
            let mut len = u64::from(h[1] & 0x7F);
            if len == 126 {
                let mut l = [0u8; 2];
                s.read_exact(&mut l).unwrap_or_else(|e| panic!("{e}"));
                len = u64::from(u16::from_be_bytes(l));
            } else if len == 127 {
                let mut l = [0u8; 8];
                s.read_exact(&mut l).unwrap_or_else(|e| panic!("{e}"));
                len = u64::from_be_bytes(l);
            }
            let mut payload = vec![0u8; usize::try_from(len).unwrap_or(0)];
            s.read_exact(&mut payload).unwrap_or_else(|e| panic!("payload: {e}"));
            match h[0] & 0x0F {
                9 => send(&mut s, 10, &payload),
                1 => {
                    let reply: Value = serde_json::from_slice(&payload).unwrap_or(Value::Null);
                    if reply["id"] == request["id"] {
                        replies.push(reply);
                        break;
                    }
                }
                _ => {}
            }
        }
    }
    replies
}

/// `thermode emulate --link LINK`; returns once the link exists.
fn emulate_on(link: &Path) -> Process {
    let mut child = Command::new(binary())
        .args(["emulate", "--channels", "2", "--link"])
        .arg(link)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap_or_else(|e| panic!("spawn emulate: {e}"));
    let mut line = String::new();
    let stdout = child.stdout.take().unwrap_or_else(|| panic!("stdout"));
    BufReader::new(stdout)
        .read_line(&mut line)
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        wait_until(LIVENESS_S, || std::fs::read_link(link).is_ok()),
        "no link at {}",
        link.display()
    );
    Process(child)
}

/// `thermode serve` with `args`; returns it, its HTTP port and a reader of its standard error.
pub(crate) fn serve_with(args: &[&str]) -> (Process, u16, std::sync::mpsc::Receiver<String>) {
    let child = Command::new(binary())
        .arg("serve")
        .args(["--port", "0"])
        .arg("--state-dir")
        .arg(own_state_dir())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("spawn serve: {e}"));
    banner(child)
}

/// A state directory of this daemon's own: the default one is locked by whichever daemon holds it, so tests run in
/// parallel (or any other `thermode serve` on the machine) would refuse each other's start.
fn own_state_dir() -> std::path::PathBuf {
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    std::env::temp_dir().join(format!("thermode-cli-state-{}-{n}", std::process::id()))
}

fn banner(mut child: Child) -> (Process, u16, std::sync::mpsc::Receiver<String>) {
    let stdout = child.stdout.take().unwrap_or_else(|| panic!("stdout"));
    let stderr = child.stderr.take().unwrap_or_else(|| panic!("stderr"));
    let process = Process(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = tx.send(line);
        }
    });
    let mut port = None;
    let mut lines = BufReader::new(stdout).lines();
    for line in lines.by_ref() {
        let line = line.unwrap_or_else(|e| panic!("serve stdout: {e}"));
        if line.contains("dashboard") {
            port = line
                .split("127.0.0.1:")
                .nth(1)
                .and_then(|rest| rest.split(['/', ' ']).next())
                .and_then(|p| p.parse::<u16>().ok());
        }
        if line.starts_with("press Ctrl-C") || line.starts_with("running for") {
            break;
        }
    }
    std::thread::spawn(move || lines.for_each(drop));
    (process, port.unwrap_or_else(|| panic!("no port in the banner")), rx)
}

/// Clears both channels' faults (retrying while fresh samples arrive), asks channel 0 for 38 °C and returns its
/// sensor before and 1.5 s after, on one WebSocket (its contact lasts as long as the connection).
fn clear_and_render(port: u16) -> (f64, f64) {
    for channel in 0..2 {
        let cleared = wait_until(LIVENESS_S, || {
            let r = ws_ask(
                port,
                &[serde_json::json!({"type": "clear_fault", "id": 1, "channel": channel})],
            );
            r[0]["type"] == "ok"
        });
        assert!(cleared, "clear_fault on channel {channel}");
    }
    let sensor = |port| status(port)["channels"][0]["sensor_c"].as_f64().unwrap_or(f64::NAN);
    let before = sensor(port);
    let r = ws_ask(
        port,
        &[serde_json::json!({"type": "setpoint", "id": 1, "channel": 0, "temp_c": 38, "rate_c_s": 5})],
    );
    assert_eq!(r[0]["type"], "ok", "{}", r[0]);
    // The contact is released 2 s after the connection closed; the sensor is read before that.
    std::thread::sleep(Duration::from_millis(1500));
    (before, sensor(port))
}

#[test]
fn the_serial_link_recovers_from_a_stopped_and_from_a_restarted_emulator() {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let link = dir.path().join("port");
    let emulator = emulate_on(&link);
    let device = format!("serial:{}", link.display());
    let (_serve, port, stderr) = serve_with(&["--device", &device, "--no-osc"]);
    let link_state = |port| status(port)["link"].clone();
    assert_eq!(link_state(port)["state"], "up");
    // The link stops while the plates rest: a link lost while a drive heats at full current counts its unseen time
    // at the envelope's bound on the plate (docs/security.md), which can spend the dose budget within seconds. After
    // the start-up self-test the controllers first bring the plates from the emulator's start to the air's rest.
    let resting = |port| {
        let channels = status(port)["channels"].clone();
        (0..2).all(|c| channels[c]["current_a"].as_f64().is_some_and(|a| a.abs() < 0.3))
    };
    assert!(
        wait_until(LIVENESS_S, || resting(port)),
        "the plates never came to rest"
    );
    signal(&emulator.0, Signal::SIGSTOP);
    assert!(
        wait_until(LIVENESS_S, || link_state(port)["state"] == "down"),
        "{}",
        link_state(port)
    );
    std::thread::sleep(Duration::from_secs(3));
    signal(&emulator.0, Signal::SIGCONT);
    assert!(
        wait_until(LIVENESS_S, || link_state(port)["reconnects"] == 1
            && link_state(port)["state"] == "up"),
        "{}",
        link_state(port)
    );
    let (before, after) = clear_and_render(port);
    assert!(
        after > before + 0.5,
        "renders after SIGSTOP/SIGCONT: {before} → {after} °C"
    );
    drop(emulator);
    assert!(
        wait_until(LIVENESS_S, || link_state(port)["state"] == "down"),
        "{}",
        link_state(port)
    );
    let _second = emulate_on(&link);
    assert!(
        wait_until(LIVENESS_S, || link_state(port)["reconnects"] == 2
            && link_state(port)["state"] == "up"),
        "{}",
        link_state(port)
    );
    let (before, after) = clear_and_render(port);
    assert!(
        after > before + 0.5,
        "renders on the restarted emulator: {before} → {after} °C"
    );
    let lines: Vec<String> = stderr.try_iter().collect();
    assert!(
        lines.iter().any(|l| l.contains("link DOWN")) && lines.iter().any(|l| l.contains("back up")),
        "stderr: {lines:?}"
    );
}

#[test]
fn serve_with_a_token_ignores_an_osc_setpoint() {
    let free = UdpSocket::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let osc_port = free.local_addr().unwrap_or_else(|e| panic!("{e}")).port();
    drop(free);
    let (_serve, port, _stderr) = serve_with(&["--token", "s3cret-t0ken", "--osc-port", &osc_port.to_string()]);
    let sender = UdpSocket::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let message = super::serve_on_emulator::osc("/thermode/channel/2/setpoint", &[40.0, 5.0]);
    for _ in 0..5 {
        let _ = sender.send_to(&message, ("127.0.0.1", osc_port));
    }
    std::thread::sleep(Duration::from_millis(500));
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap_or_else(|e| panic!("{e}"));
    write!(
        s,
        "GET /api/status HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer s3cret-t0ken\r\nConnection: close\r\n\r\n"
    )
    .unwrap_or_else(|e| panic!("{e}"));
    let mut response = String::new();
    s.read_to_string(&mut response).unwrap_or_else(|e| panic!("{e}"));
    let body: Value = serde_json::from_str(response.split("\r\n\r\n").nth(1).unwrap_or("null")).unwrap_or(Value::Null);
    assert_eq!(body["osc"]["enabled"], false, "{}", body["osc"]);
    assert_eq!(
        body["contacts"],
        serde_json::json!([]),
        "the UDP set-point was ignored: {}",
        body["contacts"]
    );
    assert_eq!(body["channels"][2]["mode"], "air", "{}", body["channels"][2]);
}

/// A temporary folder and the mount point in it where a test's own mount namespace can mount a 64 KiB tmpfs, or
/// `None` (with a SKIPPED line) where `unshare -m` is not allowed.
fn small_tmpfs_mount_point() -> Option<(tempfile::TempDir, std::path::PathBuf)> {
    let dir = tempfile::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let mount = dir.path().join("small");
    std::fs::create_dir_all(&mount).unwrap_or_else(|e| panic!("{e}"));
    let probe = Command::new("unshare")
        .args(["-m", "sh", "-c"])
        .arg(format!("mount -t tmpfs -o size=64k tmpfs {}", mount.display()))
        .output();
    if !probe.is_ok_and(|o| o.status.success()) {
        eprintln!("SKIPPED: cannot mount a tmpfs in a mount namespace here (unshare -m needs privileges)");
        return None;
    }
    Some((dir, mount))
}

/// `serve ARGUMENTS` in a mount namespace of its own with a 64 KiB tmpfs mounted at `mount`: its pid, the process,
/// its HTTP port and its standard error lines.
fn serve_on_small_tmpfs(
    mount: &std::path::Path,
    arguments: &str,
) -> (u32, Process, u16, std::sync::mpsc::Receiver<String>) {
    let script = format!(
        "mount -t tmpfs -o size=64k tmpfs {m} && exec {bin} serve {arguments}",
        m = mount.display(),
        bin = binary()
    );
    let child = Command::new("unshare")
        .args(["-m", "sh", "-c", &script])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("spawn: {e}"));
    let pid = child.id();
    let (serve, port, stderr) = banner(child);
    (pid, serve, port, stderr)
}

#[test]
fn a_recording_on_a_full_tmpfs_fails_loudly_with_whole_rows_and_stops_every_stimulus() {
    let Some((_dir, mount)) = small_tmpfs_mount_point() else {
        return;
    };
    let m = mount.display();
    // Its ledger beside the mount point, so the machine's own ledger (another display's) cannot refuse it.
    let state = mount.with_file_name("state");
    let arguments = format!(
        "--port 0 --no-osc --channels 5 --record {m} --state-dir {}",
        state.display()
    );
    let (pid, mut serve, port, stderr) = serve_on_small_tmpfs(&mount, &arguments);
    let r = ws_ask(
        port,
        &[serde_json::json!({"type": "setpoint", "id": 1, "channel": 0, "temp_c": 36, "rate_c_s": 2})],
    );
    assert_eq!(r[0]["type"], "ok", "{}", r[0]);
    assert!(
        wait_until(LIVENESS_S, || status(port)["recording"]["state"] == "failed"),
        "{}",
        status(port)["recording"]
    );
    let s = status(port);
    // The file as the daemon sees it, through its own mount namespace.
    let path = s["recording"]["path"].as_str().unwrap_or_default().to_string();
    let bytes = std::fs::read(format!("/proc/{pid}/root{path}")).unwrap_or_else(|e| panic!("read {path}: {e}"));
    let rows = bytes.iter().filter(|&&b| b == b'\n').count() as u64 - 1;
    assert_eq!(bytes.last(), Some(&b'\n'), "the file ends with a whole row");
    assert_eq!(
        s["recording"]["rows_written"].as_u64(),
        Some(rows),
        "{}",
        s["recording"]
    );
    assert!(
        s["recording"]["error"].as_str().is_some_and(|e| e.contains("space")),
        "{}",
        s["recording"]
    );
    assert!(
        wait_until(LIVENESS_S, || {
            let s = status(port);
            s["contacts"] == serde_json::json!([])
                && (0..5).all(|i| s["channels"][i]["current_a"] == 0.0 || s["channels"][i]["held_off"] == true)
        }),
        "no channel left rendering: {}",
        status(port)["channels"]
    );
    assert!(
        wait_until(LIVENESS_S, || stderr.try_iter().any(|l| l.contains("FAILED"))),
        "the failure on standard error"
    );
    // Stopped by SIGTERM, a run whose recording failed exits 2 and its summary line says so.
    signal(&serve.0, Signal::SIGTERM);
    let code = serve.0.wait().unwrap_or_else(|e| panic!("wait: {e}"));
    let mut summary = String::new();
    wait_until(LIVENESS_S, || {
        summary.extend(stderr.try_iter().map(|l| l + "\n"));
        summary.contains("SIGTERM: stopped")
    });
    assert_eq!(code.code(), Some(2), "exit {code:?}; stderr: {summary}");
    assert!(
        summary
            .lines()
            .any(|l| l.contains("SIGTERM: stopped") && l.contains("the recording FAILED")),
        "the summary line names the failed recording: {summary}"
    );
}

/// A disk that fills mid-session: `serve --state-dir` on a 64 KiB tmpfs (own mount namespace, `unshare`; skipped
/// where that is not allowed) heating one channel at 42 °C over OSC; the test fills the tmpfs. The ledger's write
/// fails, so every stimulus stops, a new one is refused (`dose_not_recorded`), the status and standard error say
/// why; once space is freed the next write lifts the hold and the ledger on disk holds at least the dose reported
/// while it could not be written. Before, the session went on and a restart forgot the dose.
#[test]
fn a_state_directory_that_fills_up_stops_heating_until_the_ledger_is_written_again() {
    let Some((_dir, mount)) = small_tmpfs_mount_point() else {
        return;
    };
    let free = UdpSocket::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let osc_port = free.local_addr().unwrap_or_else(|e| panic!("{e}")).port();
    drop(free);
    let m = mount.display();
    let arguments = format!("--port 0 --osc-port {osc_port} --channels 1 --state-dir {m}/state");
    let (pid, mut serve, port, stderr) = serve_on_small_tmpfs(&mount, &arguments);
    let sender = UdpSocket::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("{e}"));
    let heat = super::serve_on_emulator::osc("/thermode/channel/0/setpoint", &[42.0, 5.0]);
    sender
        .send_to(&heat, ("127.0.0.1", osc_port))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        wait_until(LIVENESS_S, || status(port)["dose_ledger"]["writes"].as_u64() >= Some(3)),
        "the ledger is written while heating: {}",
        status(port)["dose_ledger"]
    );
    // Fill the tmpfs, as the daemon sees it through its own mount namespace.
    let inside = format!("/proc/{pid}/root{}", mount.display());
    let filler = format!("{inside}/filler");
    let mut file = std::fs::File::create(&filler).unwrap_or_else(|e| panic!("{filler}: {e}"));
    while file.write_all(&[0u8; 4096]).is_ok() {}
    drop(file);
    assert!(
        wait_until(LIVENESS_S, || status(port)["dose_ledger"]["stimuli_refused"] == true),
        "a full disk did not stop heating: {}",
        status(port)["dose_ledger"]
    );
    let s = status(port);
    assert!(
        s["dose_ledger"]["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("space")),
        "{}",
        s["dose_ledger"]
    );
    let held_cem43 = s["channels"][0]["cem43_min"].as_f64().unwrap_or(f64::NAN);
    assert!(
        wait_until(LIVENESS_S, || status(port)["contacts"] == serde_json::json!([])),
        "still heating: {}",
        status(port)["contacts"]
    );
    sender
        .send_to(&heat, ("127.0.0.1", osc_port))
        .unwrap_or_else(|e| panic!("{e}"));
    assert!(
        wait_until(LIVENESS_S, || status(port)["osc"]["last_error"]
            .as_str()
            .is_some_and(|e| e.contains("dose_not_recorded"))),
        "a new stimulus is refused: {}",
        status(port)["osc"]
    );
    let mut told = String::new();
    wait_until(LIVENESS_S, || {
        told.extend(stderr.try_iter().map(|l| l + "\n"));
        told.contains("the dose ledger cannot be written")
    });
    assert!(told.contains("the dose ledger cannot be written"), "stderr: {told}");

    std::fs::remove_file(&filler).unwrap_or_else(|e| panic!("{filler}: {e}"));
    assert!(
        wait_until(LIVENESS_S, || status(port)["dose_ledger"]["stimuli_refused"] == false),
        "still refused after space was freed: {}",
        status(port)["dose_ledger"]
    );
    wait_until(LIVENESS_S, || {
        told.extend(stderr.try_iter().map(|l| l + "\n"));
        told.contains("the dose ledger is written again")
    });
    assert!(told.contains("the dose ledger is written again"), "stderr: {told}");
    let ledger =
        std::fs::read_to_string(format!("{inside}/state/dose-ledger.json")).unwrap_or_else(|e| panic!("ledger: {e}"));
    let ledger: Value = serde_json::from_str(&ledger).unwrap_or_else(|e| panic!("ledger: {e}: {ledger}"));
    let saved = ledger["channels"][0]["cem43_min"].as_f64().unwrap_or(f64::NAN);
    println!("full state directory: dose at the hold {held_cem43} CEM43-min, on disk after it {saved}");
    assert!(
        saved >= held_cem43,
        "ledger {saved} below the dose reported while the disk was full {held_cem43}"
    );
    signal(&serve.0, Signal::SIGTERM);
    let code = serve.0.wait().unwrap_or_else(|e| panic!("wait: {e}"));
    assert_eq!(code.code(), Some(0), "exit {code:?}");
}
