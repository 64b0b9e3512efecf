//! The request scheduler: a priority queue of wanted tiles feeding a pool of worker threads.
//!
//! * Every frame the engine [`Scheduler::submit`]s the selection's wanted list. Queued tiles
//!   that are no longer wanted are cancelled before they start; new ones are queued; the
//!   queue is re-ordered by the new priorities. Duplicates merge (a tile is queued or in
//!   flight at most once).
//! * Workers take the highest priority tile, load it (decoding and mesh building included)
//!   and send the outcome through a bounded channel.
//! * The render thread collects outcomes with [`Scheduler::drain`], which never blocks.
//!
//! A panic inside a source is caught and reported as a failure of that one tile.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;

use crossbeam_channel::{Receiver, Sender, bounded};
use globus_tiling::{TileKey, TileRequest};
use rustc_hash::FxHashSet;

use crate::{SourceError, TileSource};

/// What became of a request.
#[derive(Debug)]
pub enum Outcome<T> {
    /// The tile.
    Loaded(Arc<T>),
    /// The source has no data for it.
    NoData,
    /// Loading failed.
    Failed(SourceError),
}

/// Counters since the scheduler started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SchedulerStats {
    /// Tiles queued (each distinct queueing counts once).
    pub requested: u64,
    /// Queued tiles dropped before they started because nobody wanted them any more.
    pub cancelled: u64,
    /// Tiles loaded.
    pub loaded: u64,
    /// Tiles the source had no data for.
    pub no_data: u64,
    /// Tiles that failed.
    pub failed: u64,
}

struct Queue {
    /// Ascending priority: the last element is taken next.
    pending: Vec<(f64, TileKey)>,
    queued: FxHashSet<TileKey>,
    in_flight: FxHashSet<TileKey>,
    shutdown: bool,
    stats: SchedulerStats,
}

struct Shared<S: ?Sized> {
    source: Arc<S>,
    queue: Mutex<Queue>,
    wake: Condvar,
}

impl<S: ?Sized> Shared<S> {
    fn lock(&self) -> MutexGuard<'_, Queue> {
        // A worker never panics while holding the lock (loads run unlocked), so a poisoned
        // lock still holds consistent data.
        self.queue.lock().unwrap_or_else(|p| p.into_inner())
    }
}

type Message<T> = (TileKey, Outcome<T>);

/// Worker priority on the crate's 0 (lowest) to 99 scale; 37 maps to nice 5 on Linux.
const WORKER_PRIORITY: u8 = 37;

/// Runs a [`TileSource`]'s loads on worker threads in priority order.
pub struct Scheduler<S: TileSource + ?Sized> {
    shared: Arc<Shared<S>>,
    results: Option<Receiver<Message<S::Tile>>>,
    workers: Vec<JoinHandle<()>>,
}

impl<S: TileSource + ?Sized> Scheduler<S> {
    /// Starts `workers` threads (at least one) loading from `source`.
    pub fn new(source: Arc<S>, workers: usize) -> Self {
        let workers = workers.max(1);
        let shared = Arc::new(Shared {
            source,
            queue: Mutex::new(Queue {
                pending: Vec::new(),
                queued: FxHashSet::default(),
                in_flight: FxHashSet::default(),
                shutdown: false,
                stats: SchedulerStats::default(),
            }),
            wake: Condvar::new(),
        });
        let (tx, rx) = bounded(workers * 4);
        let handles = (0..workers)
            .map(|i| {
                let shared = Arc::clone(&shared);
                let tx = tx.clone();
                std::thread::Builder::new()
                    .name(format!("globus-tile-worker-{i}"))
                    .spawn(move || worker(&shared, &tx))
                    .map_err(|e| format!("cannot start a tile worker thread: {e}"))
            })
            .filter_map(|r| r.inspect_err(|e| eprintln!("globus: {e}")).ok())
            .collect();
        Self {
            shared,
            results: Some(rx),
            workers: handles,
        }
    }

    /// Replaces the wanted set with `requests`. Tiles in flight keep loading; tiles already
    /// loaded must not be requested (the caller knows what it holds).
    pub fn submit(&self, requests: &[TileRequest]) {
        let mut q = self.shared.lock();
        let q = &mut *q;
        let old: FxHashSet<TileKey> = std::mem::take(&mut q.queued);
        q.pending.clear();
        for r in requests {
            if q.in_flight.contains(&r.key) || !q.queued.insert(r.key) {
                continue;
            }
            if !old.contains(&r.key) {
                q.stats.requested += 1;
            }
            q.pending.push((r.priority, r.key));
        }
        q.stats.cancelled += old.iter().filter(|k| !q.queued.contains(k)).count() as u64;
        q.pending
            .sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.level().cmp(&a.1.level())));
        drop(old);
        if !q.pending.is_empty() {
            self.shared.wake.notify_all();
        }
    }

    /// Outcomes that arrived since the last call, without blocking.
    pub fn drain(&self) -> Vec<(TileKey, Outcome<S::Tile>)> {
        let mut out = Vec::new();
        if let Some(rx) = &self.results {
            // Empty or disconnected both mean nothing more to take now.
            while let Ok(m) = rx.try_recv() {
                out.push(m);
            }
        }
        out
    }

    /// Blocks until an outcome arrives or `timeout` passes (for offline rendering, which
    /// waits for loads on purpose).
    pub fn wait_one(&self, timeout: std::time::Duration) -> Option<(TileKey, Outcome<S::Tile>)> {
        self.results.as_ref()?.recv_timeout(timeout).ok()
    }

    /// Tiles queued but not started.
    pub fn queued(&self) -> usize {
        self.shared.lock().pending.len()
    }

    /// Tiles being loaded right now.
    pub fn in_flight(&self) -> usize {
        self.shared.lock().in_flight.len()
    }

    /// Whether `key` is queued or in flight.
    pub fn is_pending(&self, key: TileKey) -> bool {
        let q = self.shared.lock();
        q.queued.contains(&key) || q.in_flight.contains(&key)
    }

    /// Counters.
    pub fn stats(&self) -> SchedulerStats {
        self.shared.lock().stats
    }

    /// The source.
    pub fn source(&self) -> &Arc<S> {
        &self.shared.source
    }
}

impl<S: TileSource + ?Sized> Drop for Scheduler<S> {
    fn drop(&mut self) {
        {
            let mut q = self.shared.lock();
            q.shutdown = true;
            q.pending.clear();
        }
        self.shared.wake.notify_all();
        // Dropping the receiver releases workers blocked on a full channel.
        self.results = None;
        for w in self.workers.drain(..) {
            let _ = w.join();
        }
    }
}

fn worker<S: TileSource + ?Sized>(shared: &Shared<S>, tx: &Sender<Message<S::Tile>>) {
    // Loading is background work: somewhat below the render thread (about nice 5 on Linux),
    // so frames stay smooth on a machine with few cores while tiles still stream in.
    // Failing to lower it only costs smoothness.
    if let Ok(value) = thread_priority::ThreadPriorityValue::try_from(WORKER_PRIORITY) {
        let _ = thread_priority::set_current_thread_priority(
            thread_priority::ThreadPriority::Crossplatform(value),
        );
    }
    loop {
        let key = {
            let mut q = shared.lock();
            loop {
                if q.shutdown {
                    return;
                }
                if let Some((_, key)) = q.pending.pop() {
                    q.queued.remove(&key);
                    q.in_flight.insert(key);
                    break key;
                }
                q = shared.wake.wait(q).unwrap_or_else(|p| p.into_inner());
            }
        };
        let source = &shared.source;
        let outcome = match catch_unwind(AssertUnwindSafe(|| source.load(key))) {
            Ok(Ok(Some(tile))) => Outcome::Loaded(Arc::new(tile)),
            Ok(Ok(None)) => Outcome::NoData,
            Ok(Err(e)) => Outcome::Failed(e),
            Err(panic) => Outcome::Failed(SourceError::Failed {
                key,
                source_name: source.name().to_string(),
                message: format!("the source panicked: {}", panic_message(&*panic)),
            }),
        };
        {
            let mut q = shared.lock();
            match &outcome {
                Outcome::Loaded(_) => q.stats.loaded += 1,
                Outcome::NoData => q.stats.no_data += 1,
                Outcome::Failed(_) => q.stats.failed += 1,
            }
        }
        let sent = tx.send((key, outcome)).is_ok();
        shared.lock().in_flight.remove(&key);
        if !sent {
            return;
        }
    }
}

fn panic_message(p: &(dyn std::any::Any + Send)) -> String {
    p.downcast_ref::<&str>()
        .map(|s| (*s).to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

#[cfg(test)]
mod tests {
    use super::*;
    use globus_tiling::TilingScheme;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    /// Records the order of loads; tiles with x == 13 panic, x == 14 have no data.
    struct Recorder {
        order: Mutex<Vec<TileKey>>,
        gate: Mutex<bool>,
        started: AtomicUsize,
    }

    impl TileSource for Recorder {
        type Tile = u32;
        fn name(&self) -> &str {
            "recorder"
        }
        fn scheme(&self) -> TilingScheme {
            TilingScheme::Geographic
        }
        fn load(&self, key: TileKey) -> Result<Option<u32>, SourceError> {
            self.started.fetch_add(1, Ordering::SeqCst);
            while !*self.gate.lock().unwrap() {
                std::thread::sleep(Duration::from_millis(1));
            }
            self.order.lock().unwrap().push(key);
            match key.x() {
                13 => panic!("boom"),
                14 => Ok(None),
                x => Ok(Some(x)),
            }
        }
        fn byte_size(&self, _: &u32) -> usize {
            4
        }
    }

    fn req(x: u32, p: f64) -> TileRequest {
        TileRequest {
            key: TileKey::new(5, x, 0),
            priority: p,
        }
    }

    fn collect(s: &Scheduler<Recorder>, n: usize) -> Vec<(TileKey, Outcome<u32>)> {
        let mut out = Vec::new();
        while out.len() < n {
            out.extend(s.wait_one(Duration::from_secs(10)));
        }
        out
    }

    #[test]
    fn loads_by_priority_cancels_stale_and_survives_panics() {
        let src = Arc::new(Recorder {
            order: Mutex::new(Vec::new()),
            gate: Mutex::new(false),
            started: AtomicUsize::new(0),
        });
        let s = Scheduler::new(Arc::clone(&src), 1);
        // The single worker takes the first request and blocks on the gate.
        s.submit(&[req(1, 1.0)]);
        while src.started.load(Ordering::SeqCst) == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
        s.submit(&[
            req(2, 1.0),
            req(3, 5.0),
            req(4, 3.0),
            req(13, 0.5),
            req(14, 0.4),
        ]);
        // The camera moved: 2 is no longer wanted, 1 is still in flight (not queued again).
        s.submit(&[
            req(1, 9.0),
            req(3, 5.0),
            req(4, 3.0),
            req(13, 0.5),
            req(14, 0.4),
            req(4, 3.0),
        ]);
        *src.gate.lock().unwrap() = true;
        let out = collect(&s, 5);
        let order: Vec<u32> = src.order.lock().unwrap().iter().map(|k| k.x()).collect();
        assert_eq!(order, vec![1, 3, 4, 13, 14]);
        assert!(matches!(out[3].1, Outcome::Failed(_)));
        assert!(matches!(out[4].1, Outcome::NoData));
        let st = s.stats();
        assert_eq!(
            (st.loaded, st.failed, st.no_data, st.cancelled),
            (3, 1, 1, 1)
        );
        if let Outcome::Failed(e) = &out[3].1 {
            assert!(e.to_string().contains("5/13/0") && e.to_string().contains("boom"));
        }
    }

    #[test]
    fn drop_with_work_queued_does_not_hang() {
        let src = Arc::new(Recorder {
            order: Mutex::new(Vec::new()),
            gate: Mutex::new(true),
            started: AtomicUsize::new(0),
        });
        let s = Scheduler::new(src, 2);
        let many: Vec<TileRequest> = (0..500).map(|x| req(x % 60, f64::from(x))).collect();
        s.submit(&many);
        drop(s);
    }
}
