//! The threat model's rules (docs/security.md): loopback by default; a non-loopback bind without a token refuses
//! to start; with a token every HTTP request and WebSocket must present it; other web sites (Origin) and DNS
//! rebinding (Host) are refused; the connection count is limited. A refused stranger changes nothing.

use crate::common;

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::Arc;

use common::{ask, client_runtime, http_get, start, test_config, trackers, SpyDevice};
use thermode_platform::{Clock, MonotonicClock};
use thermode_serve::api::NetLimits;
use thermode_serve::{Daemon, ServeError, ServerConfig, DEFAULT_OSC_PORT, DEFAULT_PORT};
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;

/// Opens a WebSocket with extra headers; the HTTP status of a refused handshake, or 101.
async fn ws_status(addr: SocketAddr, query: &str, headers: &[(&str, &str)]) -> u16 {
    let mut request = format!("ws://{addr}/api/ws{query}")
        .into_client_request()
        .expect("request");
    for (k, v) in headers {
        let name: tokio_tungstenite::tungstenite::http::HeaderName = k.parse().expect("header name");
        request
            .headers_mut()
            .insert(name, HeaderValue::from_str(v).expect("header value"));
    }
    match tokio_tungstenite::connect_async(request).await {
        Ok((_, response)) => response.status().as_u16(),
        Err(tokio_tungstenite::tungstenite::Error::Http(response)) => response.status().as_u16(),
        Err(e) => panic!("unexpected WebSocket error {e}"),
    }
}

#[test]
fn the_default_is_loopback_on_fixed_ports() {
    let config = ServerConfig::default();
    assert_eq!(config.bind, IpAddr::V4(Ipv4Addr::LOCALHOST));
    assert!(config.bind.is_loopback() && config.token.is_none());
    assert_eq!((config.port, config.osc_port), (DEFAULT_PORT, Some(DEFAULT_OSC_PORT)));
    assert!(config.validate().is_ok());
}

#[test]
fn a_non_loopback_bind_without_a_token_refuses_to_start() {
    for bind in ["0.0.0.0", "::", "192.0.2.7"] {
        let mut config = test_config();
        config.server.bind = bind.parse().expect("address");
        let clock: Arc<dyn Clock> = Arc::new(MonotonicClock::new());
        let started = Daemon::start(config, Box::new(SpyDevice::new(1)), trackers(), clock);
        match started {
            Err(e @ ServeError::InsecureBind { .. }) => {
                let text = e.to_string();
                assert!(text.contains("--token") && text.contains(bind), "{text}");
            }
            other => panic!("{bind}: expected InsecureBind, got {other:?}"),
        }
    }
    let with_token = ServerConfig {
        bind: "0.0.0.0".parse().expect("address"),
        token: Some("a-long-random-secret".into()),
        ..ServerConfig::default()
    };
    assert!(with_token.validate().is_ok());
    assert!(
        !with_token.osc_enabled(),
        "OSC cannot carry the token: off on non-loopback binds"
    );
    for bad in ["", "has space", "tab\t"] {
        let config = ServerConfig {
            token: Some(bad.into()),
            ..ServerConfig::default()
        };
        assert!(
            matches!(config.validate(), Err(ServeError::Config(_))),
            "token {bad:?} accepted"
        );
    }
}

#[test]
fn with_a_token_every_request_must_present_it() {
    let mut config = test_config();
    config.server.token = Some("s3cret-t0ken".into());
    let daemon = start(config, SpyDevice::new(2), trackers());
    let addr = daemon.http_addr();
    assert!(
        daemon.dashboard_url().ends_with("/?token=s3cret-t0ken"),
        "{}",
        daemon.dashboard_url()
    );
    for path in ["/", "/api/status", "/api/materials", "/api/ws"] {
        let (code, body) = http_get(addr, path, &[]);
        assert_eq!(code, 401, "{path} without token: {body}");
        assert!(body.contains("unauthorized"), "{body}");
        let (code, _) = http_get(addr, path, &[("Authorization", "Bearer wrong-token")]);
        assert_eq!(code, 401, "{path} with a wrong token");
    }
    let (code, _) = http_get(addr, "/api/status", &[("Authorization", "Bearer s3cret-t0ken")]);
    assert_eq!(code, 200);
    let (code, _) = http_get(addr, "/api/status?token=s3cret-t0ken", &[]);
    assert_eq!(code, 200);
    client_runtime().block_on(async {
        assert_eq!(ws_status(addr, "", &[]).await, 401);
        assert_eq!(ws_status(addr, "?token=s3cret-t0keX", &[]).await, 401);
        assert_eq!(
            ws_status(addr, "", &[("authorization", "Bearer s3cret-t0ken")]).await,
            101
        );
        let mut ws = common::ws_connect(addr, "?token=s3cret-t0ken").await;
        let r = ask(&mut ws, r#"{"type":"touch","id":1,"channel":0,"material":"wood"}"#).await;
        assert_eq!(r["type"], "ok", "{r}");
    });
}

#[test]
fn other_web_sites_and_rebound_host_names_are_refused() {
    let daemon = start(test_config(), SpyDevice::new(2), trackers());
    let addr = daemon.http_addr();
    let port = addr.port();
    let (code, body) = http_get(addr, "/api/status", &[("Host", &format!("attacker.example:{port}"))]);
    assert_eq!(code, 403, "DNS rebinding: {body}");
    let (code, _) = http_get(addr, "/api/status", &[("Host", &format!("localhost:{port}"))]);
    assert_eq!(code, 200);
    client_runtime().block_on(async {
        let evil = ws_status(addr, "", &[("origin", "http://attacker.example")]).await;
        assert_eq!(evil, 403, "a foreign page must not open the WebSocket");
        let own = format!("http://{addr}");
        assert_eq!(ws_status(addr, "", &[("origin", own.as_str())]).await, 101);
    });
    let status = common::get_json(addr, "/api/status");
    assert_eq!(
        status["contacts"],
        serde_json::json!([]),
        "the strangers changed nothing"
    );
}

#[test]
fn the_number_of_websocket_connections_is_limited() {
    let mut config = test_config();
    config.server.net = NetLimits {
        max_connections: 2,
        ..NetLimits::default()
    };
    let daemon = start(config, SpyDevice::new(1), trackers());
    let addr = daemon.http_addr();
    client_runtime().block_on(async {
        let _a = common::ws_connect(addr, "").await;
        let _b = common::ws_connect(addr, "").await;
        assert_eq!(ws_status(addr, "", &[]).await, 503);
        drop(_a);
        let freed = async {
            for _ in 0..200 {
                if ws_status(addr, "", &[]).await == 101 {
                    return true;
                }
                tokio::time::sleep(std::time::Duration::from_millis(25)).await;
            }
            false
        };
        assert!(freed.await, "a closed connection frees its slot");
    });
}
