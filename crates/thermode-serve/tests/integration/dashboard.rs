//! The dashboard in a real browser: the daemon runs in-process (simulated display, render pipelines, ephemeral
//! port); Debian's headless Chromium loads the page and is driven over the Chrome DevTools Protocol. From the page
//! the test picks aluminium on channel 0 and presses Touch, sees the plot take the new samples and the target fall,
//! sees `/api/status` report the contact, saves a screenshot, presses STOP ALL and sees every contact released.
//!
//! Without `/usr/bin/chromium` the test fails when `CI` is set and is skipped loudly otherwise. Set
//! `THERMODE_DASHBOARD_PNG=/path/file.png` to keep a copy of the screenshot.

use crate::common;

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

use common::{client_runtime, get_json, pipelines, start, test_config, SpyDevice};
use futures_util::{SinkExt, StreamExt};
use serde_json::{json, Value};
use tokio_tungstenite::tungstenite::Message;

const CHROMIUM: &str = "/usr/bin/chromium";

/// The browser process; killed (by its own handle) when dropped.
struct Browser(Child);

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Starts headless Chromium and returns it with its DevTools port (read from its standard error).
fn launch(profile: &Path) -> (Browser, u16) {
    let mut child = Command::new(CHROMIUM)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--disable-dev-shm-usage",
            "--window-size=1400,1000",
            "--remote-debugging-port=0",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg("about:blank")
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("chromium starts");
    let stderr = child.stderr.take().expect("stderr");
    let browser = Browser(child);
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            if let Some(rest) = line.split("DevTools listening on ws://").nth(1) {
                let port = rest.split(['/', ':']).nth(1).and_then(|p| p.parse::<u16>().ok());
                let _ = tx.send(port);
            }
        }
    });
    let port = rx
        .recv_timeout(Duration::from_secs(60))
        .ok()
        .flatten()
        .expect("Chromium printed its DevTools address within 60 s");
    (browser, port)
}

/// A DevTools session on one page.
struct Cdp {
    ws: common::Ws,
    next_id: u64,
}

impl Cdp {
    async fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let text = json!({"id": id, "method": method, "params": params}).to_string();
        self.ws.send(Message::Text(text.into())).await.expect("CDP send");
        loop {
            let item = tokio::time::timeout(Duration::from_secs(30), self.ws.next())
                .await
                .unwrap_or_else(|_| panic!("{method}: no answer within 30 s"))
                .expect("CDP open")
                .expect("CDP frame");
            let Message::Text(text) = item else { continue };
            let reply: Value = serde_json::from_str(text.as_str()).expect("CDP JSON");
            if reply["id"] == id {
                assert!(reply.get("error").is_none(), "{method}: {reply}");
                return reply["result"].clone();
            }
        }
    }

    /// Evaluates `expression` in the page and returns its value.
    async fn eval(&mut self, expression: &str) -> Value {
        let result = self
            .call(
                "Runtime.evaluate",
                json!({"expression": expression, "returnByValue": true}),
            )
            .await;
        assert!(result.get("exceptionDetails").is_none(), "{expression}: {result}");
        result["result"]["value"].clone()
    }

    /// Polls `expression` until it is `true` (at most `limit_s`).
    async fn wait_for(&mut self, expression: &str, limit_s: f64) -> bool {
        let start = std::time::Instant::now();
        while start.elapsed().as_secs_f64() < limit_s {
            if self.eval(expression).await == Value::Bool(true) {
                return true;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        false
    }
}

/// Decodes standard base64 (the screenshot).
fn base64_decode(text: &str) -> Vec<u8> {
    let value = |c: u8| match c {
        b'A'..=b'Z' => c - b'A',
        b'a'..=b'z' => c - b'a' + 26,
        b'0'..=b'9' => c - b'0' + 52,
        b'+' => 62,
        b'/' => 63,
        _ => panic!("not base64: {c}"),
    };
    let clean: Vec<u8> = text
        .bytes()
        .filter(|&c| c != b'=' && !c.is_ascii_whitespace())
        .collect();
    let mut out = Vec::with_capacity(clean.len() * 3 / 4);
    for chunk in clean.chunks(4) {
        let mut acc = 0u32;
        for (i, &c) in chunk.iter().enumerate() {
            acc |= u32::from(value(c)) << (18 - 6 * i);
        }
        let bytes = acc.to_be_bytes();
        out.extend_from_slice(&bytes[1..chunk.len()]);
    }
    out
}

#[test]
fn the_dashboard_touches_plots_and_stops_in_a_real_browser() {
    if !Path::new(CHROMIUM).exists() {
        assert!(
            std::env::var_os("CI").is_none(),
            "{CHROMIUM} is missing: CI must install Debian's `chromium`"
        );
        eprintln!(
            "\n*** SKIPPED the dashboard browser test: {CHROMIUM} is not installed (apt-get install chromium) ***\n"
        );
        return;
    }
    let daemon = start(test_config(), SpyDevice::new(5), pipelines());
    let addr = daemon.http_addr();
    // The daemon runs a while before the page opens: its history back-fills the plots.
    std::thread::sleep(Duration::from_millis(1500));
    let history = get_json(addr, "/api/history");
    assert!(
        history["time_s"].as_array().is_some_and(|t| t.len() >= 5),
        "the daemon keeps a history: {history}"
    );
    assert_eq!(history["channels"].as_array().map(Vec::len), Some(5));
    let tmp = tempfile::tempdir().expect("temp dir");
    let (_browser, devtools_port) = launch(&tmp.path().join("profile"));
    let devtools = std::net::SocketAddr::from(([127, 0, 0, 1], devtools_port));
    let targets = get_json(devtools, "/json/list");
    let page_ws = targets
        .as_array()
        .and_then(|list| list.iter().find(|t| t["type"] == "page"))
        .and_then(|t| t["webSocketDebuggerUrl"].as_str())
        .expect("a page target")
        .to_string();
    let png = client_runtime().block_on(async {
        let (ws, _) = tokio_tungstenite::connect_async(page_ws.as_str())
            .await
            .expect("CDP connect");
        let mut cdp = Cdp { ws, next_id: 0 };
        cdp.call("Page.enable", json!({})).await;
        cdp.call("Runtime.enable", json!({})).await;
        cdp.call("Page.navigate", json!({"url": daemon.dashboard_url()})).await;
        let live = "window.thermodeState && thermodeState.connected && thermodeState.telemetryCount > 5";
        assert!(
            cdp.wait_for(live, 30.0).await,
            "the page connected and receives telemetry"
        );
        let backfilled = cdp.eval("thermodeState.historyPoints").await;
        assert!(
            backfilled.as_u64().is_some_and(|n| n >= 5),
            "the plots were back-filled from /api/history on load: {backfilled}"
        );
        assert_eq!(cdp.eval("document.querySelectorAll('canvas').length").await, json!(5));
        assert_eq!(
            cdp.eval("document.getElementById('contact-0').textContent").await,
            json!("air")
        );
        let options = cdp
            .eval("[...document.getElementById('material-0').options].map(o => o.value)")
            .await;
        assert!(
            options.as_array().is_some_and(|o| o.contains(&json!("aluminium"))),
            "{options}"
        );
        let picked = cdp
            .eval(
                "const s = document.getElementById('material-0'); s.value = 'aluminium'; \
                 s.dispatchEvent(new Event('change')); document.getElementById('touch-0').click(); s.value",
            )
            .await;
        assert_eq!(picked, json!("aluminium"));
        let shown = "document.getElementById('contact-0').textContent === 'aluminium'";
        assert!(cdp.wait_for(shown, 10.0).await, "the page shows the contact");
        // The plot's samples: the target of channel 0 must fall well below where it started.
        let fell =
            "(() => { const s = thermodeState.channels[0].series; const t = s.map(r => r[1]).filter(v => v !== null); \
                    return s.length > 20 && Math.min(...t) < t[0] - 1.0; })()";
        assert!(
            cdp.wait_for(fell, 20.0).await,
            "the plotted target falls after touching aluminium"
        );
        let status = get_json(addr, "/api/status");
        assert_eq!(
            common::shows(&status["channels"][0]),
            "aluminium",
            "the API reports the page's touch"
        );
        assert_eq!(status["contacts"].as_array().map(Vec::len), Some(1));
        // Units, the plain-language loop health and no Clear without a fault.
        let units = "document.querySelector('#nums-0').textContent.includes('°C') && \
                     document.querySelector('#nums-0').textContent.includes(' A') && \
                     document.querySelector('.legend').textContent.includes('s')";
        assert!(cdp.wait_for(units, 5.0).await, "the numbers carry units");
        let health = "/^Loop (healthy|strained|failing)$/.test(document.getElementById('health').textContent) && \
                      document.getElementById('health').title.includes('missed')";
        assert!(
            cdp.wait_for(health, 5.0).await,
            "the loop health badge with its figures on hover"
        );
        assert_eq!(
            cdp.eval("document.getElementById('clear-0').style.display").await,
            json!("none"),
            "Clear is hidden without a fault"
        );
        // A material other than the first on channel 1; after a reload its picker shows it.
        let other = cdp
            .eval(
                "const o = document.getElementById('material-1'); o.value = o.options[o.options.length - 1].value; \
                 document.getElementById('touch-1').click(); o.value",
            )
            .await;
        let other = other.as_str().expect("a material").to_string();
        assert_ne!(other, "aluminium");
        let touched = format!("document.getElementById('contact-1').textContent === '{other}'");
        assert!(cdp.wait_for(&touched, 10.0).await, "channel 1 touches {other}");
        cdp.call("Page.reload", json!({})).await;
        assert!(cdp.wait_for(live, 30.0).await, "the page reconnects after a reload");
        let pickers = format!(
            "document.getElementById('material-0').value === 'aluminium' && \
             document.getElementById('material-1').value === '{other}'"
        );
        assert!(
            cdp.wait_for(&pickers, 10.0).await,
            "after a reload the pickers show the touched materials"
        );
        let shot = cdp.call("Page.captureScreenshot", json!({"format": "png"})).await;
        let png = base64_decode(shot["data"].as_str().expect("screenshot data"));
        cdp.eval("document.getElementById('stop-all').click(); true").await;
        let all_air = "[0,1,2,3,4].every(i => document.getElementById('contact-' + i).textContent === 'air')";
        assert!(
            cdp.wait_for(all_air, 10.0).await,
            "every badge shows air after STOP ALL"
        );
        // The status's off_reason (held_off after a stop-all) is said in words under each card.
        let said = "document.getElementById('fault-0').textContent.startsWith('stopped: drive held at 0 A')";
        assert!(
            cdp.wait_for(said, 10.0).await,
            "the card says why the channel is off: {}",
            cdp.eval("document.getElementById('fault-0').textContent").await
        );
        png
    });
    let status = get_json(addr, "/api/status");
    for c in status["channels"].as_array().expect("channels") {
        assert_eq!(
            (common::shows(c).as_str(), c["held_off"].as_bool()),
            ("air", Some(true)),
            "{c}"
        );
    }
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "a PNG screenshot");
    let path = tmp.path().join("dashboard.png");
    std::fs::write(&path, &png).expect("write screenshot");
    if let Some(copy) = std::env::var_os("THERMODE_DASHBOARD_PNG") {
        std::fs::write(copy, &png).expect("copy screenshot");
    }
}
