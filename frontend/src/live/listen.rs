//! The live server's connections, accepted here rather than by
//! `axum::serve` so that a client that never finishes its request cannot
//! hold the server: a connection must send its whole request header within
//! [`HEADER_TIMEOUT`], and at most [`MAX_PENDING`] connections may be
//! still sending one. A connection past that closes the one that has been
//! sending its header longest (sockets left open on purpose are the
//! oldest; a page's header takes milliseconds), unless that one is younger
//! than 100 ms (a burst), when the newcomer is closed instead: idle
//! sockets cannot keep a page out, and a burst cannot push one out. Pages once connected are capped by `MAX_CLIENTS` where
//! the WebSocket is accepted.

use axum::Router;
use hyper::body::Incoming;
use hyper::Request;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::collections::VecDeque;
use std::future::Future;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};
use tokio::net::TcpListener;
use tower::ServiceExt;

/// Connections still sending their request header, at most.
pub const MAX_PENDING: usize = 32;

/// How long a connection may take to send its request header.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);

/// A connection this young is not closed to make room (a page's header
/// comes within milliseconds of its connection).
const GRACE: Duration = Duration::from_millis(100);

/// A connection still sending its request header.
struct Pending {
    since: Instant,
    /// Cleared when its first request's header is read.
    sending: Arc<AtomicBool>,
    task: tokio::task::AbortHandle,
}

/// Serves `app` on `listener` until `stop` completes.
pub async fn serve(listener: TcpListener, app: Router, stop: impl Future<Output = ()>) {
    let mut pending: VecDeque<Pending> = VecDeque::new();
    tokio::pin!(stop);
    loop {
        let stream = tokio::select! {
            r = listener.accept() => match r {
                Ok((s, _)) => s,
                // Out of descriptors, say: the listener stays; try again
                // shortly rather than spin.
                Err(_) => {
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            _ = &mut stop => return,
        };
        pending.retain(|p| p.sending.load(Ordering::Relaxed) && !p.task.is_finished());
        if pending.len() >= MAX_PENDING {
            // The oldest goes, unless it is younger than GRACE (a burst of
            // connections): then the newest does, so a page that came
            // just before a burst keeps its place.
            match pending.front() {
                Some(oldest) if oldest.since.elapsed() >= GRACE => {
                    oldest.task.abort();
                    pending.pop_front();
                }
                _ => {
                    drop(stream);
                    continue;
                }
            }
        }
        // Frames go out as soon as they are written (a header and its
        // image are two messages: Nagle's algorithm would hold the second).
        let _ = stream.set_nodelay(true);
        let sending = Arc::new(AtomicBool::new(true));
        let app = app.clone();
        let flag = sending.clone();
        let task = tokio::spawn(async move {
            let svc = tower::service_fn(move |req: Request<Incoming>| {
                flag.store(false, Ordering::Relaxed);
                app.clone().oneshot(req)
            });
            let _ = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT)
                .serve_connection(TokioIo::new(stream), TowerToHyperService::new(svc))
                .with_upgrades()
                .await;
        });
        pending.push_back(Pending {
            since: Instant::now(),
            sending,
            task: task.abort_handle(),
        });
    }
}
