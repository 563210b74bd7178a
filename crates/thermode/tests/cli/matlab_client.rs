//! The MATLAB/Octave client (`clients/matlab`) run under Debian's `octave-cli` against this build's `thermode
//! serve` (the simulated display, with a token): `clients/matlab/tests/run_client_tests.m` checks every request,
//! its reply and the refusals raised as `thermode:<code>` errors; then the example
//! (`clients/matlab/examples/cold_detection_threshold.m`) runs one method-of-limits run with a simulated press.
//! Octave talks to the daemon through a recording proxy (a few lines of HTTP below): every JSON request the client
//! sends and every reply it receives, in both runs, is then validated against the published protocol schema
//! (`docs/protocol.schema.json`: requests as `ClientMessage`, replies as `Response`) by Python's `jsonschema`
//! (draft 2020-12), as the Python and JavaScript clients' tests validate theirs.
//! CI installs `octave-cli`, `curl` and `jsonschema` and sets `THERMODE_REQUIRE_OCTAVE_TESTS=1`, so there a missing
//! tool fails the test; elsewhere it is skipped with a message saying what to install.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};

use super::service::serve_with;

/// `octave-cli` evaluating `code` with the client and its tests on the path, against the daemon at `url`.
fn octave(repo: &Path, url: &str, token: &str, code: &str) -> (bool, String) {
    let matlab = repo.join("clients/matlab");
    let path = format!(
        "addpath('{}', '{}', '{}');",
        matlab.display(),
        matlab.join("tests").display(),
        matlab.join("examples").display()
    );
    let out = Command::new("octave-cli")
        .args(["--no-gui", "--norc", "--quiet", "--eval"])
        .arg(format!("{path} {code}"))
        .env("THERMODE_URL", url)
        .env("THERMODE_TOKEN", token)
        .output()
        .unwrap_or_else(|e| panic!("run octave-cli: {e}"));
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.success(), report)
}

/// One request through the proxy: the request's body, the HTTP status and the reply's body.
#[derive(Debug, Clone)]
struct Exchange {
    request: String,
    status: u16,
    reply: String,
}

/// A proxy on a free local port in front of the daemon on `daemon_port`: each connection's request is forwarded
/// (with `Connection: close`), the daemon's response handed back unchanged, and both bodies kept in the log.
fn recording_proxy(daemon_port: u16) -> (u16, Arc<Mutex<Vec<Exchange>>>) {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap_or_else(|e| panic!("proxy: {e}"));
    let port = listener.local_addr().unwrap_or_else(|e| panic!("proxy: {e}")).port();
    let log = Arc::new(Mutex::new(Vec::new()));
    let kept = Arc::clone(&log);
    std::thread::spawn(move || {
        for client in listener.incoming().map_while(Result::ok) {
            let kept = Arc::clone(&kept);
            std::thread::spawn(move || {
                if let Ok(exchange) = forward(client, daemon_port) {
                    kept.lock().unwrap_or_else(|e| e.into_inner()).push(exchange);
                }
            });
        }
    });
    (port, log)
}

/// Forwards one HTTP request from `client` to the daemon and its response back.
fn forward(mut client: TcpStream, daemon_port: u16) -> std::io::Result<Exchange> {
    let mut bytes = Vec::new();
    let mut buffer = [0u8; 4096];
    let head_end = loop {
        if let Some(end) = bytes.windows(4).position(|w| w == b"\r\n\r\n") {
            break end;
        }
        let n = client.read(&mut buffer)?;
        if n == 0 {
            return Err(std::io::ErrorKind::UnexpectedEof.into());
        }
        bytes.extend_from_slice(&buffer[..n]);
    };
    let head = String::from_utf8_lossy(&bytes[..head_end]).into_owned();
    let header = |name: &str| {
        head.lines()
            .find_map(|l| l.split_once(':').filter(|(n, _)| n.eq_ignore_ascii_case(name)))
            .map(|(_, v)| v.trim().to_string())
    };
    if header("expect").is_some_and(|v| v.eq_ignore_ascii_case("100-continue")) {
        client.write_all(b"HTTP/1.1 100 Continue\r\n\r\n")?;
    }
    let length: usize = header("content-length").and_then(|v| v.parse().ok()).unwrap_or(0);
    let mut body = bytes[head_end + 4..].to_vec();
    while body.len() < length {
        let n = client.read(&mut buffer)?;
        if n == 0 {
            break;
        }
        body.extend_from_slice(&buffer[..n]);
    }
    let kept_lines: Vec<&str> = head
        .split("\r\n")
        .filter(|l| {
            let name = l.split(':').next().unwrap_or("").trim().to_ascii_lowercase();
            name != "connection" && name != "expect"
        })
        .collect();
    let mut daemon = TcpStream::connect(("127.0.0.1", daemon_port))?;
    daemon.write_all(format!("{}\r\nConnection: close\r\n\r\n", kept_lines.join("\r\n")).as_bytes())?;
    daemon.write_all(&body)?;
    let mut response = Vec::new();
    daemon.read_to_end(&mut response)?;
    client.write_all(&response)?;
    let (status, reply) = response_body(&response);
    Ok(Exchange {
        request: String::from_utf8_lossy(&body).into_owned(),
        status,
        reply,
    })
}

/// The status and body of a whole HTTP response (a chunked body joined).
fn response_body(response: &[u8]) -> (u16, String) {
    let text = String::from_utf8_lossy(response);
    let (head, body) = text.split_once("\r\n\r\n").unwrap_or((&text, ""));
    let status = head.split_whitespace().nth(1).and_then(|s| s.parse().ok()).unwrap_or(0);
    if !head.to_ascii_lowercase().contains("transfer-encoding: chunked") {
        return (status, body.to_string());
    }
    let (mut joined, mut rest) = (String::new(), body);
    while let Some((size, after)) = rest.split_once("\r\n") {
        let size = usize::from_str_radix(size.trim(), 16).unwrap_or(0);
        if size == 0 || after.len() < size {
            break;
        }
        joined.push_str(&after[..size]);
        rest = after[size..].trim_start_matches("\r\n");
    }
    (status, joined)
}

/// Validates every request of `log` as the schema's `ClientMessage` and every reply as its `Response` with
/// Python's `jsonschema`; also checks that the validator refuses a request with a field the protocol lacks. The
/// script's report and whether every message was valid; `None` when `jsonschema` is missing.
fn validate_against_schema(repo: &Path, log: &[Exchange]) -> Option<(bool, String)> {
    let has_jsonschema = Command::new("python3")
        .args(["-c", "import jsonschema"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_jsonschema {
        return None;
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let messages: Vec<serde_json::Value> = log
        .iter()
        .map(|e| serde_json::json!({"request": e.request, "status": e.status, "reply": e.reply}))
        .collect();
    let file = dir.path().join("messages.json");
    std::fs::write(&file, serde_json::to_string(&messages).expect("json")).expect("write the messages");
    let script = r##"
import json, sys
import jsonschema
schema = json.load(open(sys.argv[1]))
def validator(name):
    return jsonschema.Draft202012Validator({"$schema": schema["$schema"], "$defs": schema["$defs"], "$ref": "#/$defs/" + name})
requests, replies = validator("ClientMessage"), validator("Response")
bad = {"type": "touch", "id": 1, "channel": 0, "material": "wood", "colour": "red"}
assert not requests.is_valid(bad), "the validator accepts a field the protocol lacks"
failures = 0
for exchange in json.load(open(sys.argv[2])):
    for validator_, text, what in ((requests, exchange["request"], "request"), (replies, exchange["reply"], "reply")):
        message = json.loads(text)
        errors = [e.message for e in validator_.iter_errors(message)][:3]
        if errors:
            failures += 1
            print(f"INVALID {what} (HTTP {exchange['status']}): {text[:300]} -> {errors}")
print(f"{len(json.load(open(sys.argv[2])))} exchanges checked, {failures} invalid")
sys.exit(1 if failures else 0)
"##;
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(repo.join("docs/protocol.schema.json"))
        .arg(&file)
        .output()
        .unwrap_or_else(|e| panic!("run python3: {e}"));
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    Some((out.status.success(), report))
}

/// The `type` of every message of `texts` (JSON objects), sorted, once each.
fn types<'a>(texts: impl Iterator<Item = &'a String>) -> Vec<String> {
    let mut types: Vec<String> = texts
        .filter_map(|t| serde_json::from_str::<serde_json::Value>(t).ok())
        .filter_map(|m| m["type"].as_str().map(str::to_string))
        .collect();
    types.sort();
    types.dedup();
    types
}

#[test]
fn the_matlab_client_and_its_example_run_under_octave_against_serve() {
    let required = std::env::var("THERMODE_REQUIRE_OCTAVE_TESTS").is_ok_and(|v| v == "1");
    let ready = Command::new("octave-cli")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    let curl = Command::new("curl")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !(ready && curl) {
        assert!(
            !required,
            "THERMODE_REQUIRE_OCTAVE_TESTS=1 but octave-cli (ready: {ready}) or curl (ready: {curl}) is missing"
        );
        println!("skipped: `apt-get install octave curl` to run the MATLAB/Octave client's tests under octave-cli");
        return;
    }
    let repo: PathBuf = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let token = "octave-t0ken";
    let (_serve, port, _stderr) = serve_with(&["--no-osc", "--token", token]);
    let (proxy_port, log) = recording_proxy(port);
    let url = format!("http://127.0.0.1:{proxy_port}");
    let (ok, report) = octave(&repo, &url, token, "run_client_tests");
    println!("{report}");
    assert!(ok, "the client's checks failed under octave-cli:\n{report}");
    assert!(report.contains("all MATLAB/Octave client checks passed"), "{report}");

    let example = "t = cold_detection_threshold(getenv('THERMODE_URL'), 'Runs', 1, 'RateCs', 5, 'RestS', 0, \
                   'SimulatedPressS', 1.0); fprintf('threshold %.4f\\n', t);";
    let (ok, report) = octave(&repo, &url, token, example);
    println!("{report}");
    assert!(ok, "the example failed under octave-cli:\n{report}");
    let threshold: f64 = report
        .lines()
        .find_map(|l| l.strip_prefix("threshold "))
        .and_then(|t| t.trim().parse().ok())
        .unwrap_or_else(|| panic!("no threshold printed:\n{report}"));
    // 1 s into a 5 °C/s ramp from 32 °C (after the step to the baseline): the set-point is about 5 °C down; the
    // lagging plate sensor reads less, and the process start and HTTP round trips add at most a few tenths.
    assert!(
        (-7.5..=-1.0).contains(&threshold),
        "threshold {threshold:.3} °C, expected between -7.5 and -1.0 °C (about -5 for a press 1 s into a \
         5 °C/s ramp)"
    );

    check_messages_against_schema(&repo, &log.lock().unwrap_or_else(|e| e.into_inner()), required);
}

/// Every message of the two Octave runs (`log`) against the published schema; the requests and replies cover the
/// client's whole vocabulary. Without `jsonschema` the check is skipped, unless `required` (CI).
fn check_messages_against_schema(repo: &Path, log: &[Exchange], required: bool) {
    let sent = types(log.iter().map(|e| &e.request));
    for kind in [
        "marker",
        "program",
        "program_stop",
        "release",
        "response",
        "setpoint",
        "status",
        "stop_all",
        "touch",
    ] {
        assert!(
            sent.iter().any(|t| t == kind),
            "no {kind} request went through the proxy: {sent:?}"
        );
    }
    let received = types(log.iter().map(|e| &e.reply));
    assert_eq!(received, ["error", "ok", "status"], "the replies' types");
    match validate_against_schema(repo, log) {
        Some((valid, report)) => {
            println!("{report}");
            assert!(
                valid,
                "messages of the Octave session not valid against the schema:\n{report}"
            );
        }
        None => {
            assert!(
                !required,
                "THERMODE_REQUIRE_OCTAVE_TESTS=1 but python3's jsonschema is missing"
            );
            println!("schema check skipped: `python3 -m pip install jsonschema` to validate the messages");
        }
    }
}
