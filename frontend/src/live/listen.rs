//! The live server's connections, accepted here rather than by
//! `axum::serve` so that a client that never finishes its request cannot
//! hold the server: a connection must send its whole request header within
//! [`HEADER_TIMEOUT`], and at most [`MAX_PENDING`] connections may be
//! still sending one (a connection past that is closed at once; a page
//! that loses the race connects again). Pages once connected are capped
//! by `MAX_CLIENTS` where the WebSocket is accepted.

use axum::Router;
use hyper::body::Incoming;
use hyper::Request;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::service::TowerToHyperService;
use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tower::ServiceExt;

/// Connections still sending their request header, at most.
pub const MAX_PENDING: usize = 32;

/// How long a connection may take to send its request header.
pub const HEADER_TIMEOUT: Duration = Duration::from_secs(5);

/// Serves `app` on `listener` until `stop` completes.
pub async fn serve(listener: TcpListener, app: Router, stop: impl Future<Output = ()>) {
    let pending = Arc::new(Semaphore::new(MAX_PENDING));
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
        let Ok(permit) = pending.clone().try_acquire_owned() else {
            drop(stream);
            continue;
        };
        // Frames go out as soon as they are written (a header and its
        // image are two messages: Nagle's algorithm would hold the second).
        let _ = stream.set_nodelay(true);
        // Released when the first request's header is read.
        let permit = Arc::new(Mutex::new(Some(permit)));
        let app = app.clone();
        tokio::spawn(async move {
            let svc = tower::service_fn(move |req: Request<Incoming>| {
                permit.lock().unwrap().take();
                app.clone().oneshot(req)
            });
            let _ = hyper::server::conn::http1::Builder::new()
                .timer(TokioTimer::new())
                .header_read_timeout(HEADER_TIMEOUT)
                .serve_connection(TokioIo::new(stream), TowerToHyperService::new(svc))
                .with_upgrades()
                .await;
        });
    }
}
