//! Who may talk to the daemon: the token (`Authorization: Bearer T` or `?token=T`, compared in constant time), the
//! Host check that defeats DNS rebinding on a loopback daemon without a token, and the Origin check that keeps
//! other web sites (which a browser lets open WebSockets anywhere) from driving the display.
//!
//! See `docs/security.md` for the threat model.

use std::net::IpAddr;

use axum::http::{header, HeaderMap};

use crate::api::protocol::{ApiError, ErrorCode};

/// The access policy of one daemon.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Access {
    token: Option<String>,
    port: u16,
    allowed_origins: Vec<String>,
}

impl Access {
    /// A policy: `token` (if any) is required on every request; the daemon listens on `port`; `allowed_origins`
    /// (e.g. `https://app.example`) may open connections besides the daemon's own pages.
    pub fn new(token: Option<String>, port: u16, allowed_origins: Vec<String>) -> Self {
        Access {
            token,
            port,
            allowed_origins,
        }
    }

    /// Whether a token is required.
    pub fn token_required(&self) -> bool {
        self.token.is_some()
    }

    /// Checks a request's headers and query string.
    pub fn check(&self, headers: &HeaderMap, query: Option<&str>) -> Result<(), ApiError> {
        let host = header_str(headers, header::HOST);
        match &self.token {
            Some(token) => {
                if !presented_token(headers, query).is_some_and(|t| constant_time_eq(t.as_bytes(), token.as_bytes())) {
                    return Err(ApiError::new(
                        ErrorCode::Unauthorized,
                        "this daemon requires its token: `Authorization: Bearer <token>` or `?token=<token>`",
                    ));
                }
            }
            None => {
                if !host.is_some_and(|h| self.is_loopback_host(h)) {
                    return Err(ApiError::new(
                        ErrorCode::Forbidden,
                        "Host must be a loopback address or localhost with the daemon's port",
                    ));
                }
            }
        }
        if let Some(origin) = header_str(headers, header::ORIGIN) {
            let own = host.is_some_and(|h| origin == format!("http://{h}"));
            if !own && !self.allowed_origins.iter().any(|o| o == origin) {
                return Err(ApiError::new(
                    ErrorCode::Forbidden,
                    format!("origin {origin:?} is not allowed (see --allow-origin)"),
                ));
            }
        }
        Ok(())
    }

    /// `localhost`, `127.x.y.z` or `[::1]`, with the daemon's port (or none).
    fn is_loopback_host(&self, host: &str) -> bool {
        let (name, port) = split_host(host);
        let port_ok = port.is_none_or(|p| p == self.port.to_string());
        let name_ok = name.eq_ignore_ascii_case("localhost")
            || name
                .trim_start_matches('[')
                .trim_end_matches(']')
                .parse::<IpAddr>()
                .is_ok_and(|ip| ip.is_loopback());
        port_ok && name_ok
    }
}

fn header_str(headers: &HeaderMap, name: header::HeaderName) -> Option<&str> {
    headers.get(name).and_then(|v| v.to_str().ok())
}

/// (`name`, `port`) of a Host header value (`[::1]:80`, `localhost:80`, `localhost`).
fn split_host(host: &str) -> (&str, Option<&str>) {
    if let Some(rest) = host.strip_prefix('[') {
        return match rest.split_once(']') {
            Some((name, tail)) => (name, tail.strip_prefix(':')),
            None => (host, None),
        };
    }
    match host.rsplit_once(':') {
        Some((name, port)) => (name, Some(port)),
        None => (host, None),
    }
}

/// The token from `Authorization: Bearer T`, else from the query's `token=T`.
fn presented_token(headers: &HeaderMap, query: Option<&str>) -> Option<String> {
    let bearer = header_str(headers, header::AUTHORIZATION)
        .and_then(|v| v.strip_prefix("Bearer "))
        .map(|t| t.trim().to_string());
    bearer.or_else(|| {
        query?
            .split('&')
            .find_map(|pair| pair.strip_prefix("token="))
            .and_then(percent_decode)
    })
}

/// Decodes `%XX` escapes and `+` (as a space); `None` on a broken escape or invalid UTF-8.
pub fn percent_decode(text: &str) -> Option<String> {
    let bytes = text.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'%' => {
                let hex = std::str::from_utf8(bytes.get(i + 1..i + 3)?).ok()?;
                out.push(u8::from_str_radix(hex, 16).ok()?);
                i += 3;
            }
            b'+' => {
                out.push(b' ');
                i += 1;
            }
            b => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

/// Compares in time that depends only on the lengths, not on where the bytes differ.
pub fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for i in 0..a.len().max(b.len()) {
        let x = a.get(i).copied().unwrap_or(0);
        let y = b.get(i).copied().unwrap_or(0);
        diff |= usize::from(x ^ y);
    }
    diff == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn headers(pairs: &[(header::HeaderName, &str)]) -> HeaderMap {
        let mut map = HeaderMap::new();
        for (name, value) in pairs {
            map.insert(name.clone(), HeaderValue::from_str(value).expect("ascii"));
        }
        map
    }

    #[test]
    fn loopback_hosts_pass_and_rebinding_hosts_fail() {
        let access = Access::new(None, 8765, vec![]);
        for host in [
            "127.0.0.1:8765",
            "localhost:8765",
            "[::1]:8765",
            "127.0.0.2:8765",
            "LOCALHOST",
        ] {
            assert!(access.check(&headers(&[(header::HOST, host)]), None).is_ok(), "{host}");
        }
        for host in ["evil.example:8765", "127.0.0.1:9999", "10.0.0.1:8765"] {
            let e = access.check(&headers(&[(header::HOST, host)]), None).expect_err(host);
            assert_eq!(e.code, ErrorCode::Forbidden, "{host}");
        }
        assert!(access.check(&HeaderMap::new(), None).is_err(), "no Host header");
    }

    #[test]
    fn foreign_origins_fail_unless_allowed() {
        let access = Access::new(None, 80, vec!["https://app.example".into()]);
        let own = headers(&[(header::HOST, "localhost:80"), (header::ORIGIN, "http://localhost:80")]);
        assert!(access.check(&own, None).is_ok());
        let foreign = headers(&[(header::HOST, "localhost:80"), (header::ORIGIN, "http://evil.example")]);
        assert_eq!(
            access.check(&foreign, None).map_err(|e| e.code),
            Err(ErrorCode::Forbidden)
        );
        let allowed = headers(&[(header::HOST, "localhost:80"), (header::ORIGIN, "https://app.example")]);
        assert!(access.check(&allowed, None).is_ok());
    }

    #[test]
    fn the_token_is_required_by_header_or_query() {
        let access = Access::new(Some("s3cret/+x".into()), 80, vec![]);
        let host = (header::HOST, "192.0.2.1:80");
        assert!(access.check(&headers(std::slice::from_ref(&host)), None).is_err());
        let bearer = headers(&[host.clone(), (header::AUTHORIZATION, "Bearer s3cret/+x")]);
        assert!(access.check(&bearer, None).is_ok());
        let wrong = headers(&[host.clone(), (header::AUTHORIZATION, "Bearer s3cret/+y")]);
        assert_eq!(
            access.check(&wrong, None).map_err(|e| e.code),
            Err(ErrorCode::Unauthorized)
        );
        assert!(access
            .check(&headers(std::slice::from_ref(&host)), Some("a=1&token=s3cret%2F%2Bx"))
            .is_ok());
        assert!(access.check(&headers(&[host]), Some("token=s3cret")).is_err());
    }

    #[test]
    fn constant_time_comparison_is_equality() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"abcd"));
        assert!(!constant_time_eq(b"", b"a"));
        assert_eq!(percent_decode("%zz"), None);
    }
}
