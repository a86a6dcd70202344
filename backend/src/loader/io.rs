//! The loader's I/O threads (G08 §4 "all data access requests are performed
//! asynchronously by a separate thread, and refinement continues only if data
//! is immediately available").
//!
//! Requests wait in a shared queue, highest priority first; the refinement of
//! each frame replaces the queued (not yet started) requests with the ones it
//! still wants, in its priority order. Each thread reads and decodes one brick
//! at a time and sends the result back on a channel, which the loader drains
//! without blocking at the start of the next frame.

use crate::store::{Brick, NodeKey, OctreeDb};
use std::collections::VecDeque;
use std::sync::mpsc::{self, Receiver, RecvError, Sender, TryRecvError};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

/// A brick read by an I/O thread: its values ((B+4)³) and stored macrocell
/// ranges (`None` when the node is not stored), or the error, as text.
pub(crate) struct Landed {
    pub key: NodeKey,
    pub result: Result<Option<Brick>, String>,
}

struct Queue {
    jobs: VecDeque<NodeKey>,
    shutdown: bool,
}

struct Shared {
    queue: Mutex<Queue>,
    wake: Condvar,
}

pub(crate) struct IoPool {
    shared: Arc<Shared>,
    results: Receiver<Landed>,
    threads: Vec<JoinHandle<()>>,
}

impl IoPool {
    pub fn new(db: Arc<OctreeDb>, threads: usize) -> Self {
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue {
                jobs: VecDeque::new(),
                shutdown: false,
            }),
            wake: Condvar::new(),
        });
        let (tx, results) = mpsc::channel();
        let threads = (0..threads.max(1))
            .map(|i| {
                let (db, shared, tx) = (db.clone(), shared.clone(), tx.clone());
                std::thread::Builder::new()
                    .name(format!("parallax-io-{i}"))
                    .spawn(move || worker(&db, &shared, &tx))
                    .expect("cannot spawn a loader I/O thread")
            })
            .collect();
        IoPool {
            shared,
            results,
            threads,
        }
    }

    /// Replaces the queued requests: `f` gets the requests no thread has
    /// started yet (in queue order) and returns the new queue.
    pub fn requeue(&self, f: impl FnOnce(Vec<NodeKey>) -> VecDeque<NodeKey>) {
        let mut q = self.shared.queue.lock().unwrap_or_else(|e| e.into_inner());
        let old: Vec<NodeKey> = q.jobs.drain(..).collect();
        q.jobs = f(old);
        let n = q.jobs.len();
        drop(q);
        match n {
            0 => {}
            1 => self.shared.wake.notify_one(),
            _ => self.shared.wake.notify_all(),
        }
    }

    pub fn try_recv(&self) -> Result<Landed, TryRecvError> {
        self.results.try_recv()
    }

    pub fn recv(&self) -> Result<Landed, RecvError> {
        self.results.recv()
    }
}

impl Drop for IoPool {
    fn drop(&mut self) {
        {
            let mut q = self.shared.queue.lock().unwrap_or_else(|e| e.into_inner());
            q.shutdown = true;
            q.jobs.clear();
        }
        self.shared.wake.notify_all();
        for t in self.threads.drain(..) {
            let _ = t.join();
        }
    }
}

fn worker(db: &OctreeDb, shared: &Shared, tx: &Sender<Landed>) {
    loop {
        let key = {
            let mut q = shared.queue.lock().unwrap_or_else(|e| e.into_inner());
            loop {
                if q.shutdown {
                    return;
                }
                if let Some(k) = q.jobs.pop_front() {
                    break k;
                }
                q = shared.wake.wait(q).unwrap_or_else(|e| e.into_inner());
            }
        };
        // A failing brick is reported, never fatal (not even a panic in the
        // decoder).
        let result = match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            db.read_brick_cells(key)
        })) {
            Ok(Ok(v)) => Ok(v),
            Ok(Err(e)) => Err(format!("{e:#}")),
            Err(_) => Err(format!(
                "{}: brick {key}: the reader panicked",
                db.path().display()
            )),
        };
        if tx.send(Landed { key, result }).is_err() {
            return;
        }
    }
}
