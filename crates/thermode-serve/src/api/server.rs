//! The HTTP/1.1 server in front of the router: its own accept loop, so that no client can starve it.
//!
//! - **A total cap** ([`NetLimits::max_http_connections`], lowered at start-up to fit the open-files limit less
//!   [`RESERVED_FILES`]). When the cap is reached, a new connection takes the place of the oldest connection that
//!   is *idle*: one that has no request in progress (still sending its request head, or kept alive between
//!   requests). Connections with a request in progress and upgraded WebSockets (capped on their own) are never
//!   taken. So a legitimate request, which sends its head at once, always gets in, however many slow or silent
//!   connections are open: STOP ALL (the WebSocket handshake) stays reachable. Only when every slot has a request in
//!   progress is a new connection closed at once.
//! - **A header-read timeout** ([`NetLimits::header_timeout_s`]): a request head must be complete within it, from
//!   the connection's start or from the first byte of a later request; else the connection is closed.
//! - **An idle timeout** ([`NetLimits::http_idle_timeout_s`]): a kept-alive connection with no request for this long
//!   is closed.
//! - **Accept errors** (out of file descriptors) never end the loop: an idle connection is closed to free one, and
//!   the accept is retried after [`ACCEPT_RETRY_MS`].
//!
//! Counters are in `/api/status` (`http`).

use std::collections::BTreeMap;
use std::convert::Infallible;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicU8, Ordering};
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use axum::body::Body;
use axum::extract::Request;
use axum::response::Response;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::TokioIo;
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::Notify;
use tokio::time::Instant;

use super::NetLimits;

/// Files kept free for everything but HTTP connections (the device, the recording, OSC, the runtime's own) when
/// the connection cap is fitted to the open-files limit.
pub const RESERVED_FILES: u64 = 64;
/// Smallest connection cap whatever the open-files limit.
pub const MIN_HTTP_CONNECTIONS: usize = 8;
/// Wait before retrying a failed accept \[ms\].
pub const ACCEPT_RETRY_MS: u64 = 10;
/// How often a connection checks its timeouts \[ms\].
const CHECK_INTERVAL_MS: u64 = 250;
/// Largest request head \[bytes\].
const MAX_HEAD_BYTES: usize = 32 * 1024;

const IDLE: u8 = 0;
const ACTIVE: u8 = 1;
const UPGRADED: u8 = 2;

/// What the server has done, for `/api/status`.
#[derive(Debug, Default)]
pub struct HttpCounters {
    /// Connections accepted.
    pub accepted: AtomicU64,
    /// Connections open now (upgraded WebSockets included).
    pub open: AtomicU64,
    /// Idle connections closed to make room for a new one (at the cap, or out of file descriptors).
    pub evicted: AtomicU64,
    /// Connections closed by the header-read or idle timeout.
    pub timed_out: AtomicU64,
    /// New connections closed at once: every slot had a request in progress.
    pub refused: AtomicU64,
    /// Failed accepts (e.g. out of file descriptors).
    pub accept_errors: AtomicU64,
    /// `POST /api/command` requests whose body was read (answered, refused or rate-limited).
    pub commands: AtomicU64,
}

/// The connection cap for an open-files limit: the configured cap, at most the limit less [`RESERVED_FILES`], at
/// least [`MIN_HTTP_CONNECTIONS`].
pub fn fitted_cap(configured: usize, open_files_limit: Option<u64>) -> usize {
    let room = open_files_limit.map_or(usize::MAX, |n| {
        usize::try_from(n.saturating_sub(RESERVED_FILES)).unwrap_or(usize::MAX)
    });
    configured.min(room).max(MIN_HTTP_CONNECTIONS)
}

/// One connection as the server tracks it.
#[derive(Debug)]
pub struct Slot {
    id: u64,
    state: AtomicU8,
    /// Milliseconds since the registry's origin after which an idle connection is closed.
    deadline_ms: AtomicU64,
    /// Idle after a response: the next byte starts the header-read timeout.
    awaiting_request: AtomicBool,
    /// Chosen for eviction (skipped when choosing again).
    evicting: AtomicBool,
    evict: Notify,
}

impl Slot {
    /// The WebSocket handshake succeeded: the connection is the WebSocket's now (never evicted, its own timeouts).
    pub fn upgraded(&self) {
        self.state.store(UPGRADED, Ordering::SeqCst);
    }
}

/// The open connections, oldest first.
#[derive(Debug)]
struct Registry {
    slots: Mutex<BTreeMap<u64, Arc<Slot>>>,
    next_id: AtomicU64,
    origin: Instant,
    cap: usize,
    header_ms: u64,
    idle_ms: u64,
    counters: Arc<HttpCounters>,
}

impl Registry {
    fn now_ms(&self) -> u64 {
        u64::try_from(self.origin.elapsed().as_millis()).unwrap_or(u64::MAX)
    }

    /// A slot for a new connection, making room by evicting the oldest idle connection at the cap; `None` if every
    /// slot has a request in progress.
    fn admit(self: &Arc<Self>) -> Option<Member> {
        let mut slots = self.slots.lock().unwrap_or_else(|p| p.into_inner());
        let live = slots.values().filter(|s| !s.evicting.load(Ordering::SeqCst)).count();
        if live >= self.cap && !Registry::evict_oldest_idle(&slots, &self.counters) {
            self.counters.refused.fetch_add(1, Ordering::Relaxed);
            return None;
        }
        let id = self.next_id.fetch_add(1, Ordering::Relaxed);
        let slot = Arc::new(Slot {
            id,
            state: AtomicU8::new(IDLE),
            deadline_ms: AtomicU64::new(self.now_ms().saturating_add(self.header_ms)),
            awaiting_request: AtomicBool::new(false),
            evicting: AtomicBool::new(false),
            evict: Notify::new(),
        });
        slots.insert(id, slot.clone());
        self.counters.open.fetch_add(1, Ordering::Relaxed);
        Some(Member {
            registry: self.clone(),
            slot,
        })
    }

    /// Frees a slot (out of file descriptors); true if one was chosen.
    fn make_room(&self) -> bool {
        let slots = self.slots.lock().unwrap_or_else(|p| p.into_inner());
        Registry::evict_oldest_idle(&slots, &self.counters)
    }

    fn evict_oldest_idle(slots: &BTreeMap<u64, Arc<Slot>>, counters: &HttpCounters) -> bool {
        let victim = slots
            .values()
            .find(|s| s.state.load(Ordering::SeqCst) == IDLE && !s.evicting.load(Ordering::SeqCst));
        match victim {
            Some(victim) => {
                victim.evicting.store(true, Ordering::SeqCst);
                victim.evict.notify_one();
                counters.evicted.fetch_add(1, Ordering::Relaxed);
                true
            }
            None => false,
        }
    }

    /// Whether `slot` is idle past its deadline.
    fn expired(&self, slot: &Slot) -> bool {
        slot.state.load(Ordering::SeqCst) == IDLE && self.now_ms() > slot.deadline_ms.load(Ordering::SeqCst)
    }
}

/// A connection's membership of the registry; leaving it (drop) frees the slot.
#[derive(Debug)]
struct Member {
    registry: Arc<Registry>,
    slot: Arc<Slot>,
}

impl Drop for Member {
    fn drop(&mut self) {
        let mut slots = self.registry.slots.lock().unwrap_or_else(|p| p.into_inner());
        slots.remove(&self.slot.id);
        self.registry.counters.open.fetch_sub(1, Ordering::Relaxed);
    }
}

/// The socket, holding the connection's membership for as long as it lives (through an upgrade too), and noting
/// the first byte of a request after an idle period.
struct Tracked {
    stream: TcpStream,
    member: Member,
}

impl AsyncRead for Tracked {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        let before = buf.filled().len();
        let result = Pin::new(&mut self.stream).poll_read(cx, buf);
        if buf.filled().len() > before && self.member.slot.awaiting_request.swap(false, Ordering::SeqCst) {
            let registry = &self.member.registry;
            let deadline = registry.now_ms().saturating_add(registry.header_ms);
            self.member.slot.deadline_ms.store(deadline, Ordering::SeqCst);
        }
        result
    }
}

impl AsyncWrite for Tracked {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        Pin::new(&mut self.stream).poll_write(cx, buf)
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_flush(cx)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.stream).poll_shutdown(cx)
    }
}

/// Marks a connection busy while a request is handled; idle again (the idle timeout running) afterwards.
struct Busy {
    registry: Arc<Registry>,
    slot: Arc<Slot>,
}

impl Busy {
    fn new(registry: Arc<Registry>, slot: Arc<Slot>) -> Self {
        let _ = slot
            .state
            .compare_exchange(IDLE, ACTIVE, Ordering::SeqCst, Ordering::SeqCst);
        Busy { registry, slot }
    }
}

impl Drop for Busy {
    fn drop(&mut self) {
        let deadline = self.registry.now_ms().saturating_add(self.registry.idle_ms);
        self.slot.deadline_ms.store(deadline, Ordering::SeqCst);
        self.slot.awaiting_request.store(true, Ordering::SeqCst);
        let _ = self
            .slot
            .state
            .compare_exchange(ACTIVE, IDLE, Ordering::SeqCst, Ordering::SeqCst);
    }
}

/// The per-connection service: the router, with the connection marked busy while it answers and its [`Slot`] in
/// the request's extensions (the WebSocket handshake marks it upgraded).
#[derive(Clone)]
struct Handler {
    router: TowerToHyperService<Router>,
    registry: Arc<Registry>,
    slot: Arc<Slot>,
}

impl hyper::service::Service<hyper::Request<Incoming>> for Handler {
    type Response = Response;
    type Error = Infallible;
    type Future = Pin<Box<dyn Future<Output = Result<Response, Infallible>> + Send>>;

    fn call(&self, request: hyper::Request<Incoming>) -> Self::Future {
        let busy = Busy::new(self.registry.clone(), self.slot.clone());
        let mut request: Request = request.map(Body::new);
        request.extensions_mut().insert(self.slot.clone());
        let answer = self.router.call(request);
        Box::pin(async move {
            let response = answer.await;
            drop(busy);
            response
        })
    }
}

/// Serves `router` on `listener` until the runtime stops. `cap` is the fitted connection cap.
pub async fn serve(listener: TcpListener, router: Router, limits: NetLimits, cap: usize, counters: Arc<HttpCounters>) {
    let registry = Arc::new(Registry {
        slots: Mutex::new(BTreeMap::new()),
        next_id: AtomicU64::new(0),
        origin: Instant::now(),
        cap,
        header_ms: (limits.header_timeout_s * 1000.0) as u64,
        idle_ms: (limits.http_idle_timeout_s * 1000.0) as u64,
        counters: counters.clone(),
    });
    let router = TowerToHyperService::new(router);
    loop {
        let stream = match listener.accept().await {
            Ok((stream, _peer)) => stream,
            Err(_) => {
                counters.accept_errors.fetch_add(1, Ordering::Relaxed);
                registry.make_room();
                tokio::time::sleep(Duration::from_millis(ACCEPT_RETRY_MS)).await;
                continue;
            }
        };
        counters.accepted.fetch_add(1, Ordering::Relaxed);
        let Some(member) = registry.admit() else {
            drop(stream);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let handler = Handler {
            router: router.clone(),
            registry: registry.clone(),
            slot: member.slot.clone(),
        };
        tokio::spawn(connection(Tracked { stream, member }, handler));
    }
}

/// One connection: HTTP/1.1 with upgrades, until it ends, is evicted or times out.
async fn connection(io: Tracked, handler: Handler) {
    let (registry, slot) = (handler.registry.clone(), handler.slot.clone());
    let conn = hyper::server::conn::http1::Builder::new()
        .max_buf_size(MAX_HEAD_BYTES)
        .serve_connection(TokioIo::new(io), handler)
        .with_upgrades();
    tokio::pin!(conn);
    let mut check = tokio::time::interval(Duration::from_millis(CHECK_INTERVAL_MS));
    loop {
        tokio::select! {
            _ = &mut conn => return,
            () = slot.evict.notified() => return,
            _ = check.tick() => {
                if registry.expired(&slot) {
                    registry.counters.timed_out.fetch_add(1, Ordering::Relaxed);
                    return;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cap_fits_the_open_files_limit() {
        assert_eq!(fitted_cap(128, None), 128);
        assert_eq!(fitted_cap(128, Some(256)), 128);
        assert_eq!(fitted_cap(128, Some(100)), 36);
        assert_eq!(fitted_cap(128, Some(10)), MIN_HTTP_CONNECTIONS);
    }
}
