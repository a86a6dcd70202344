//! The loader's I/O threads (G08 §4 "all data access requests are performed
//! asynchronously by a separate thread, and refinement continues only if data
//! is immediately available").
//!
//! Requests wait in a shared queue, highest priority first; the refinement of
//! each frame replaces the queued (not yet started) requests with the ones it
//! still wants, in its priority order. Each thread reads and decodes one brick
//! at a time and sends the result back on a channel, which the loader drains
//! without blocking at the start of the next frame.

use crate::store::{Brick, LayerBricks, NodeKey, OctreeDb};
use parallax_common::tf::EmptinessTable;
use std::collections::VecDeque;
use std::sync::mpsc::{self, Receiver, RecvError, Sender, TryRecvError};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;

/// A brick read by an I/O thread: its values ((B+4)³) and stored macrocell
/// ranges (`None` when the node is not stored), or the error, as text.
pub(crate) struct Landed {
    pub key: NodeKey,
    /// The brick, and the bytes read from the databases for it.
    pub result: Result<(Option<Brick>, u64), String>,
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
    /// Threads reading `sources`: the scene volume, then its registered
    /// layers (each with its emptiness under its transfer function).
    pub fn new(sources: Arc<Vec<Source>>, threads: usize) -> Self {
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
                let (sources, shared, tx) = (sources.clone(), shared.clone(), tx.clone());
                std::thread::Builder::new()
                    .name(format!("parallax-io-{i}"))
                    .spawn(move || worker(&sources, &shared, &tx))
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

/// A database the loader reads: the scene volume (first), or a registered
/// layer, whose bricks empty under its transfer function are never read.
pub(crate) struct Source {
    pub db: Arc<OctreeDb>,
    pub empty: Option<EmptinessTable>,
    /// A layer on another grid: resampled onto the volume's bricks.
    pub placed: Option<super::resample::Placed>,
}

/// One node's brick: the scene volume's alone, or, with registered layers,
/// with theirs (those the layer stores and its transfer function does not
/// leave empty), and the bytes read for it. `None` when no database stores
/// the node.
pub(crate) fn read_node(sources: &[Source], key: NodeKey) -> anyhow::Result<(Option<Brick>, u64)> {
    let stored = |db: &OctreeDb| {
        db.node(key)
            .filter(|r| r.is_stored())
            .map_or(0, |r| r.len as u64)
    };
    let main = sources[0].db.read_brick_cells(key)?;
    let mut bytes = stored(&sources[0].db);
    if sources.len() == 1 {
        return Ok((main, bytes));
    }
    let mut layers = Vec::with_capacity(sources.len() - 1);
    for s in &sources[1..] {
        if let (Some(p), Some(e)) = (&s.placed, &s.empty) {
            let (v, b) = match p.cover(key, e).needs_data {
                true => p.brick(key, e)?,
                false => (None, 0),
            };
            bytes += b;
            layers.push(v);
            continue;
        }
        let wanted = s.db.node(key).is_some_and(|r| {
            r.is_stored()
                && !s
                    .empty
                    .as_ref()
                    .is_some_and(|e| e.is_empty(r.min as f64, r.max as f64))
        });
        layers.push(match wanted {
            true => {
                bytes += stored(&s.db);
                s.db.read_brick_cells(key)?.map(|b| b.values)
            }
            false => None,
        });
    }
    if main.is_none() && layers.iter().all(Option::is_none) {
        return Ok((None, bytes));
    }
    let n = sources[0].db.layout().stored_len();
    let (values, cells, has_main) = match main {
        Some(b) => (b.values, b.cells, true),
        None => (vec![0.0; n], None, false),
    };
    let brick = Brick {
        values,
        cells,
        layered: Some(LayerBricks {
            main: has_main,
            layers,
        }),
    };
    Ok((Some(brick), bytes))
}

fn worker(sources: &[Source], shared: &Shared, tx: &Sender<Landed>) {
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
            read_node(sources, key)
        })) {
            Ok(Ok(v)) => Ok(v),
            Ok(Err(e)) => Err(format!("{e:#}")),
            Err(_) => Err(format!(
                "{}: brick {key}: the reader panicked",
                sources[0].db.path().display()
            )),
        };
        if tx.send(Landed { key, result }).is_err() {
            return;
        }
    }
}
