//! The request scheduler: a priority queue of wanted tiles feeding a pool of worker threads.
//!
//! * Every frame the engine [`Scheduler::submit`]s the selection's wanted list. Queued tiles
//!   that are no longer wanted are cancelled before they start; tiles in flight that are no
//!   longer wanted get their [`Cancel`] flag set, so a download stops at its next chunk and
//!   its result is dropped; new tiles are queued; the queue is re-ordered by the new
//!   priorities (ties: shallower first, so ancestors come before descendants). Duplicates
//!   merge (a tile is queued or in flight at most once).
//! * Workers take the highest-priority tile that is not waiting out a backoff, load it
//!   (fetching, decoding and mesh building included) and send the outcome through a bounded
//!   channel.
//! * Transient failures (timeouts, resets, 5xx, 429) are retried up to
//!   [`RetryPolicy::max_attempts`] times while the tile is still wanted, after an exponential
//!   backoff with jitter, or after the server's Retry-After. The [`Clock`] is injectable so
//!   tests can drive time.
//! * The render thread collects outcomes with [`Scheduler::drain`], which never blocks.
//!
//! A panic inside a source is caught and reported as a failure of that one tile.

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crossbeam_channel::{Receiver, Sender, bounded};
use globus_tiling::{TileKey, TileRequest};
use rustc_hash::{FxHashMap, FxHashSet};

use crate::fetch::Cancel;
use crate::{SourceError, TileSource};

/// What became of a request.
#[derive(Debug)]
pub enum Outcome<T> {
    /// The tile.
    Loaded(Arc<T>),
    /// The source has no data for it.
    NoData,
    /// Loading failed for good (permanently, or transiently more often than allowed).
    Failed(SourceError),
}

/// Counters since the scheduler started.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SchedulerStats {
    /// Tiles queued (each distinct queueing counts once).
    pub requested: u64,
    /// Loads started (retries included).
    pub started: u64,
    /// Queued tiles dropped before they started because nobody wanted them any more.
    pub cancelled: u64,
    /// Loads in flight told to stop because nobody wanted them any more.
    pub cancelled_in_flight: u64,
    /// Loads that stopped on cancellation and whose result was dropped.
    pub dropped: u64,
    /// Tiles loaded.
    pub loaded: u64,
    /// Tiles the source had no data for.
    pub no_data: u64,
    /// Tiles that failed for good, as reported (a failure of a load cancelled meanwhile is
    /// dropped, not counted).
    pub failed: u64,
    /// Transient failures that were scheduled for another attempt.
    pub retries: u64,
}

/// A monotonic clock (injectable for tests).
pub trait Clock: Send + Sync + 'static {
    /// Time since an arbitrary origin.
    fn now(&self) -> Duration;
}

/// The real clock.
pub struct SystemClock(Instant);

impl Default for SystemClock {
    fn default() -> Self {
        Self(Instant::now())
    }
}

impl Clock for SystemClock {
    fn now(&self) -> Duration {
        self.0.elapsed()
    }
}

/// How transient failures are retried.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RetryPolicy {
    /// Attempts per tile in all (the first included).
    pub max_attempts: u32,
    /// Backoff before the second attempt; doubles each time.
    pub base_delay: Duration,
    /// Longest backoff.
    pub max_delay: Duration,
    /// Longest Retry-After honoured (a server asking for more gets this).
    pub max_retry_after: Duration,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            max_attempts: 4,
            base_delay: Duration::from_millis(250),
            max_delay: Duration::from_secs(20),
            max_retry_after: Duration::from_secs(120),
        }
    }
}

impl RetryPolicy {
    /// The wait before attempt `failed + 1` after `failed` failures: the server's
    /// Retry-After if given, else `base * 2^(failed - 1)` capped, scaled by a jitter factor
    /// in [0.5, 1) from `jitter` in [0, 1) (so many clients do not retry in step).
    pub fn delay(&self, failed: u32, retry_after: Option<Duration>, jitter: f64) -> Duration {
        if let Some(r) = retry_after {
            return r.min(self.max_retry_after);
        }
        let exp = self
            .base_delay
            .saturating_mul(1u32 << failed.saturating_sub(1).min(20))
            .min(self.max_delay);
        exp.mul_f64(0.5 + 0.5 * jitter.clamp(0.0, 1.0))
    }
}

/// Knobs of a scheduler.
#[derive(Clone, Copy, Debug)]
pub struct SchedulerOptions {
    /// Worker threads, which is also the most loads in flight at once.
    pub workers: usize,
    /// Retrying.
    pub retry: RetryPolicy,
}

struct Queue {
    /// Ascending priority: the last element is taken next.
    pending: Vec<(f64, TileKey)>,
    queued: FxHashSet<TileKey>,
    in_flight: FxHashMap<TileKey, Cancel>,
    /// Finished and sent (or being sent), not yet collected by the consumer: neither to be
    /// cancelled nor queued again.
    done: FxHashSet<TileKey>,
    /// Tiles that failed transiently: failures so far and when they may be tried again.
    backoff: FxHashMap<TileKey, (u32, Duration)>,
    /// The last submitted priorities (to re-queue a retry while still wanted).
    wanted: FxHashMap<TileKey, f64>,
    shutdown: bool,
    stats: SchedulerStats,
    jitter_state: u64,
}

impl Queue {
    fn sort(&mut self) {
        self.pending
            .sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.level().cmp(&a.1.level())));
    }

    /// Takes the highest-priority tile not waiting out a backoff; else says how long until
    /// the first one may go.
    fn take(&mut self, now: Duration) -> Result<TileKey, Option<Duration>> {
        let mut wait: Option<Duration> = None;
        for i in (0..self.pending.len()).rev() {
            let key = self.pending[i].1;
            match self.backoff.get(&key) {
                Some(&(_, ready)) if ready > now => {
                    let w = ready - now;
                    wait = Some(wait.map_or(w, |x: Duration| x.min(w)));
                }
                _ => {
                    self.pending.remove(i);
                    self.queued.remove(&key);
                    return Ok(key);
                }
            }
        }
        Err(wait)
    }

    fn jitter(&mut self) -> f64 {
        // xorshift64*: enough to spread retries apart.
        let mut x = self.jitter_state;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.jitter_state = x;
        (x.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
}

struct Shared<S: ?Sized> {
    source: Arc<S>,
    queue: Mutex<Queue>,
    wake: Condvar,
    clock: Arc<dyn Clock>,
    retry: RetryPolicy,
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
/// Loaded tiles that may wait for the render thread's [`Scheduler::drain`] (once a frame)
/// before the workers stop to wait for it: what a stalled consumer holds outside the memory
/// budget. It bounds how many tiles a frame can take in, so it must cover a slow frame's
/// loads: four per worker (8 on two cores) held `globus bench --path paths/alps-dive.json`
/// on a software rasteriser (0.4-2 s frames) to 9-10 arrivals a frame, with the workers idle
/// most of each frame and hundreds of wanted tiles waiting.
const RESULTS_WAITING: usize = 64;
/// Longest a worker sleeps before looking at the clock again (a fake clock moves without
/// notifying).
const MAX_IDLE_WAIT: Duration = Duration::from_millis(100);

/// Runs a [`TileSource`]'s loads on worker threads in priority order.
pub struct Scheduler<S: TileSource + ?Sized> {
    shared: Arc<Shared<S>>,
    results: Option<Receiver<Message<S::Tile>>>,
    workers: Vec<JoinHandle<()>>,
}

impl<S: TileSource + ?Sized> Scheduler<S> {
    /// Starts `workers` threads (at least one) loading from `source`, retrying by default.
    pub fn new(source: Arc<S>, workers: usize) -> Self {
        Self::with_clock(
            source,
            SchedulerOptions {
                workers,
                retry: RetryPolicy::default(),
            },
            Arc::new(SystemClock::default()),
        )
    }

    /// Starts a scheduler with `options`, timing backoffs on `clock`.
    pub fn with_clock(source: Arc<S>, options: SchedulerOptions, clock: Arc<dyn Clock>) -> Self {
        let workers = options.workers.max(1);
        let shared = Arc::new(Shared {
            source,
            queue: Mutex::new(Queue {
                pending: Vec::new(),
                queued: FxHashSet::default(),
                in_flight: FxHashMap::default(),
                done: FxHashSet::default(),
                backoff: FxHashMap::default(),
                wanted: FxHashMap::default(),
                shutdown: false,
                stats: SchedulerStats::default(),
                jitter_state: 0x9E37_79B9_7F4A_7C15,
            }),
            wake: Condvar::new(),
            clock,
            retry: options.retry,
        });
        let (tx, rx) = bounded(RESULTS_WAITING.max(workers * 4));
        let handles = (0..workers)
            .map(|i| {
                let shared = Arc::clone(&shared);
                let tx = tx.clone();
                std::thread::Builder::new()
                    .name(format!("globus-tile-worker-{i}"))
                    .spawn(move || worker(&shared, &tx))
                    .map_err(|e| format!("cannot start a tile worker thread: {e}"))
            })
            .filter_map(|r| r.inspect_err(|e| tracing::error!("{e}")).ok())
            .collect();
        Self {
            shared,
            results: Some(rx),
            workers: handles,
        }
    }

    /// Replaces the wanted set with `requests`. Tiles in flight keep loading if still wanted
    /// and are told to stop if not; tiles already loaded must not be requested (the caller
    /// knows what it holds).
    pub fn submit(&self, requests: &[TileRequest]) {
        let mut q = self.shared.lock();
        let q = &mut *q;
        let old: FxHashSet<TileKey> = std::mem::take(&mut q.queued);
        q.pending.clear();
        q.wanted.clear();
        for r in requests {
            q.wanted.insert(r.key, r.priority);
            if q.in_flight.contains_key(&r.key)
                || q.done.contains(&r.key)
                || !q.queued.insert(r.key)
            {
                continue;
            }
            if !old.contains(&r.key) {
                q.stats.requested += 1;
            }
            q.pending.push((r.priority, r.key));
        }
        q.stats.cancelled += old.iter().filter(|k| !q.queued.contains(k)).count() as u64;
        for (key, cancel) in &q.in_flight {
            if !q.wanted.contains_key(key) && !cancel.is_cancelled() && !q.done.contains(key) {
                cancel.cancel();
                q.stats.cancelled_in_flight += 1;
            }
        }
        // Forget backoffs of tiles nobody has wanted for a long time.
        if q.backoff.len() > 4096 {
            let now = self.shared.clock.now();
            let wanted = &q.wanted;
            q.backoff.retain(|k, (_, ready)| {
                wanted.contains_key(k) || *ready + Duration::from_secs(600) > now
            });
        }
        q.sort();
        drop(old);
        if !q.pending.is_empty() {
            self.shared.wake.notify_all();
        }
    }

    /// Wakes the workers to look at the clock again (after a fake clock moved).
    pub fn poke(&self) {
        self.shared.wake.notify_all();
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
        self.collected(out.iter().map(|m| m.0));
        out
    }

    /// The consumer has these outcomes: their tiles may be asked for again.
    fn collected(&self, keys: impl Iterator<Item = TileKey>) {
        let mut q = self.shared.lock();
        for k in keys {
            q.done.remove(&k);
        }
    }

    /// Blocks until an outcome arrives or `timeout` passes (for offline rendering, which
    /// waits for loads on purpose).
    pub fn wait_one(&self, timeout: Duration) -> Option<(TileKey, Outcome<S::Tile>)> {
        let m = self.results.as_ref()?.recv_timeout(timeout).ok()?;
        self.collected(std::iter::once(m.0));
        Some(m)
    }

    /// Tiles queued but not started (including those waiting out a backoff).
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
        q.queued.contains(&key) || q.in_flight.contains_key(&key)
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
            for c in q.in_flight.values() {
                c.cancel();
            }
        }
        self.shared.wake.notify_all();
        // Dropping the receiver releases workers blocked on a full channel.
        self.results = None;
        // A load that ignores its cancellation (a read that never returns) must not hold the
        // program: wait a moment for each worker, then leave it behind (it holds only its own
        // reference to the source, and ends with the process).
        let deadline = Instant::now() + SHUTDOWN_WAIT;
        for w in self.workers.drain(..) {
            while !w.is_finished() && Instant::now() < deadline {
                std::thread::sleep(Duration::from_millis(2));
            }
            if w.is_finished() {
                let _ = w.join();
            } else {
                tracing::warn!(
                    "a tile loader of {} did not stop within {} s of being cancelled; leaving it behind",
                    self.shared.source.name(),
                    SHUTDOWN_WAIT.as_secs()
                );
            }
        }
    }
}

/// How long dropping a scheduler waits for its workers to stop.
pub const SHUTDOWN_WAIT: Duration = Duration::from_secs(2);

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
        let (key, cancel) = {
            let mut q = shared.lock();
            loop {
                if q.shutdown {
                    return;
                }
                match q.take(shared.clock.now()) {
                    Ok(key) => {
                        let cancel = Cancel::new();
                        q.in_flight.insert(key, cancel.clone());
                        q.stats.started += 1;
                        break (key, cancel);
                    }
                    Err(wait) => {
                        let wait = wait.map_or(MAX_IDLE_WAIT, |w| w.min(MAX_IDLE_WAIT));
                        q = shared
                            .wake
                            .wait_timeout(q, wait)
                            .map(|(g, _)| g)
                            .unwrap_or_else(|p| p.into_inner().0);
                    }
                }
            }
        };
        let source = &shared.source;
        let result = match catch_unwind(AssertUnwindSafe(|| source.load(key, &cancel))) {
            Ok(r) => r,
            Err(panic) => Err(SourceError::Failed {
                key,
                source_name: source.name().to_string(),
                message: format!("the source panicked: {}", panic_message(&*panic)),
            }),
        };
        let outcome = {
            let mut q = shared.lock();
            // Retries and dropped loads leave flight now; delivered ones once sent (so a
            // submit in between cannot queue the tile again).
            let outcome = match result {
                Ok(Some(tile)) => {
                    q.backoff.remove(&key);
                    q.stats.loaded += 1;
                    Some(Outcome::Loaded(Arc::new(tile)))
                }
                Ok(None) => {
                    q.backoff.remove(&key);
                    q.stats.no_data += 1;
                    Some(Outcome::NoData)
                }
                Err(SourceError::Cancelled { .. }) => {
                    q.stats.dropped += 1;
                    None
                }
                Err(e @ SourceError::Transient { .. }) => {
                    let failed = q.backoff.get(&key).map_or(0, |b| b.0) + 1;
                    if failed >= shared.retry.max_attempts {
                        q.backoff.remove(&key);
                        Some(Outcome::Failed(e))
                    } else {
                        let retry_after = match &e {
                            SourceError::Transient { retry_after, .. } => *retry_after,
                            _ => None,
                        };
                        let jitter = q.jitter();
                        let ready =
                            shared.clock.now() + shared.retry.delay(failed, retry_after, jitter);
                        q.backoff.insert(key, (failed, ready));
                        q.stats.retries += 1;
                        q.in_flight.remove(&key);
                        if let Some(&p) = q.wanted.get(&key)
                            && q.queued.insert(key)
                        {
                            q.pending.push((p, key));
                            q.sort();
                        }
                        None
                    }
                }
                Err(e) => {
                    q.backoff.remove(&key);
                    Some(Outcome::Failed(e))
                }
            };
            let outcome = match outcome {
                // A failure of a tile nobody wants is not worth reporting (nor counting: it
                // is asked again if it is wanted again, and counted then).
                Some(Outcome::Failed(_)) if cancel.is_cancelled() => {
                    q.stats.dropped += 1;
                    None
                }
                Some(Outcome::Failed(e)) => {
                    q.stats.failed += 1;
                    Some(Outcome::Failed(e))
                }
                other => other,
            };
            if outcome.is_none() {
                q.in_flight.remove(&key);
            }
            outcome
        };
        if let Some(outcome) = outcome {
            // Done: a submit that no longer lists it has nothing to cancel.
            shared.lock().done.insert(key);
            let sent = tx.send((key, outcome)).is_ok();
            shared.lock().in_flight.remove(&key);
            if !sent {
                return;
            }
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
    use globus_test_support::eventually;
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
        fn load(&self, key: TileKey, _: &Cancel) -> Result<Option<u32>, SourceError> {
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

    /// A load that never returns and ignores its cancellation (a loader blocked on a FIFO):
    /// the process never exited. Dropping the scheduler now returns after SHUTDOWN_WAIT.
    #[test]
    fn a_stuck_loader_does_not_hold_the_shutdown() {
        let src = Arc::new(Recorder {
            order: Mutex::new(Vec::new()),
            gate: Mutex::new(false),
            started: AtomicUsize::new(0),
        });
        let s = Scheduler::new(Arc::clone(&src), 2);
        s.submit(&[req(1, 1.0)]);
        eventually("the load starts", || {
            src.started.load(Ordering::SeqCst) == 1
        });
        let (tx, rx) = std::sync::mpsc::sync_channel(1);
        std::thread::spawn(move || {
            drop(s);
            let _ = tx.send(());
        });
        let ended = rx.recv_timeout(SHUTDOWN_WAIT * 10);
        *src.gate.lock().unwrap() = true;
        assert!(
            ended.is_ok(),
            "dropping the scheduler waited on the stuck loader"
        );
    }

    /// A clock the test moves by hand.
    #[derive(Default)]
    struct FakeClock(Mutex<Duration>);

    impl Clock for FakeClock {
        fn now(&self) -> Duration {
            *self.0.lock().unwrap()
        }
    }

    impl FakeClock {
        fn advance(&self, d: Duration) {
            *self.0.lock().unwrap() += d;
        }
    }

    /// Fails transiently `fail_times` times per tile (with `retry_after` on tile x == 1),
    /// recording when (on the fake clock) each attempt started; tile x == 9 blocks until
    /// cancelled.
    struct Flaky {
        clock: Arc<FakeClock>,
        fail_times: u32,
        attempts: Mutex<FxHashMap<TileKey, Vec<Duration>>>,
    }

    impl TileSource for Flaky {
        type Tile = u32;
        fn name(&self) -> &str {
            "flaky"
        }
        fn scheme(&self) -> TilingScheme {
            TilingScheme::Geographic
        }
        fn load(&self, key: TileKey, cancel: &Cancel) -> Result<Option<u32>, SourceError> {
            let n = {
                let mut a = self.attempts.lock().unwrap();
                let v = a.entry(key).or_default();
                v.push(self.clock.now());
                v.len() as u32
            };
            if key.x() == 9 {
                while !cancel.is_cancelled() {
                    std::thread::sleep(Duration::from_millis(1));
                }
                return Err(SourceError::Cancelled { key });
            }
            if n <= self.fail_times {
                return Err(SourceError::Transient {
                    key,
                    source_name: "flaky".into(),
                    message: "HTTP 503".into(),
                    retry_after: (key.x() == 1).then(|| Duration::from_secs(30)),
                });
            }
            Ok(Some(key.x()))
        }
        fn byte_size(&self, _: &u32) -> usize {
            4
        }
    }

    fn flaky(fail_times: u32) -> (Arc<FakeClock>, Arc<Flaky>, Scheduler<Flaky>) {
        let clock = Arc::new(FakeClock::default());
        let src = Arc::new(Flaky {
            clock: Arc::clone(&clock),
            fail_times,
            attempts: Mutex::new(FxHashMap::default()),
        });
        let options = SchedulerOptions {
            workers: 2,
            retry: RetryPolicy::default(),
        };
        let s = Scheduler::with_clock(Arc::clone(&src), options, clock.clone());
        (clock, src, s)
    }

    #[test]
    fn backoff_delays_grow_with_jitter_and_honour_retry_after() {
        let p = RetryPolicy::default();
        assert_eq!(p.delay(1, None, 0.0), Duration::from_millis(125));
        assert_eq!(p.delay(1, None, 0.999_999).as_millis(), 249);
        assert_eq!(p.delay(3, None, 0.0), Duration::from_millis(500));
        assert_eq!(p.delay(30, None, 0.0), Duration::from_secs(10));
        assert_eq!(
            p.delay(1, Some(Duration::from_secs(7)), 0.5),
            Duration::from_secs(7)
        );
        assert_eq!(
            p.delay(1, Some(Duration::from_secs(99_999)), 0.5),
            Duration::from_secs(120)
        );
    }

    #[test]
    fn transient_failures_are_retried_after_backoff_on_the_clock() {
        let (clock, src, s) = flaky(2);
        s.submit(&[req(0, 1.0)]);
        let attempts = |x: u32| {
            src.attempts
                .lock()
                .unwrap()
                .get(&TileKey::new(5, x, 0))
                .map_or(0, Vec::len)
        };
        eventually("first attempt", || attempts(0) == 1);
        eventually("first retry scheduled", || s.stats().retries == 1);
        // The clock does not move: no second attempt however long we wait.
        std::thread::sleep(Duration::from_millis(300));
        assert_eq!(attempts(0), 1);
        assert_eq!(s.stats().retries, 1);
        // After the first backoff (125..250 ms), the second attempt; after the second
        // (250..500 ms), the third, which succeeds.
        clock.advance(Duration::from_millis(250));
        s.poke();
        eventually("second attempt", || attempts(0) == 2);
        eventually("second retry scheduled", || s.stats().retries == 2);
        clock.advance(Duration::from_millis(500));
        s.poke();
        let (key, outcome) = s.wait_one(Duration::from_secs(10)).expect("outcome");
        assert_eq!(key, TileKey::new(5, 0, 0));
        assert!(matches!(outcome, Outcome::Loaded(ref v) if **v == 0));
        let times = src.attempts.lock().unwrap()[&key].clone();
        assert_eq!(
            times,
            vec![
                Duration::ZERO,
                Duration::from_millis(250),
                Duration::from_millis(750)
            ]
        );
        let st = s.stats();
        assert_eq!((st.started, st.retries, st.loaded, st.failed), (3, 2, 1, 0));
    }

    #[test]
    fn retry_after_is_honoured_and_attempts_are_bounded() {
        let (clock, src, s) = flaky(u32::MAX);
        s.submit(&[req(1, 1.0)]);
        let key = TileKey::new(5, 1, 0);
        let attempts = || src.attempts.lock().unwrap().get(&key).map_or(0, Vec::len);
        // The clock moves only once each failure's retry is scheduled (its time is taken
        // from the clock when the failure comes back, not when the attempt starts).
        eventually("first retry scheduled", || s.stats().retries == 1);
        assert_eq!(attempts(), 1);
        // Retry-After: 30 s. At 29 s nothing happens; at 30 s the second attempt.
        clock.advance(Duration::from_secs(29));
        s.poke();
        std::thread::sleep(Duration::from_millis(250));
        assert_eq!(attempts(), 1);
        for n in 2..=4 {
            clock.advance(Duration::from_secs(1));
            s.poke();
            eventually("next attempt", || attempts() == n);
            if n < 4 {
                eventually("next retry scheduled", || s.stats().retries == n as u64);
            }
            clock.advance(Duration::from_secs(29));
        }
        // Four attempts in all, then a failure naming the tile.
        let (_, outcome) = s.wait_one(Duration::from_secs(10)).expect("outcome");
        match outcome {
            Outcome::Failed(e) => {
                assert!(e.to_string().contains("5/1/0") && e.to_string().contains("503"))
            }
            other => panic!("expected a failure, got {other:?}"),
        }
        assert_eq!(s.stats().failed, 1);
    }

    #[test]
    fn unwanted_loads_are_cancelled_in_flight_and_retries_stop() {
        let (clock, src, s) = flaky(1);
        s.submit(&[req(9, 1.0), req(2, 0.5)]);
        let started = |x: u32| {
            src.attempts
                .lock()
                .unwrap()
                .contains_key(&TileKey::new(5, x, 0))
        };
        eventually("both started", || started(9) && started(2));
        // Tile 2 failed once and waits out its backoff; the camera moves on.
        eventually("retry scheduled", || s.stats().retries == 1);
        s.submit(&[req(3, 1.0)]);
        // Tile 3 fails once too; once its backoff has passed it loads.
        eventually("tile 3 failed once", || s.stats().retries == 2);
        clock.advance(Duration::from_secs(1));
        s.poke();
        let (key, outcome) = s.wait_one(Duration::from_secs(10)).expect("outcome");
        assert_eq!(key, TileKey::new(5, 3, 0));
        assert!(matches!(outcome, Outcome::Loaded(_)));
        // Tile 9 stopped when it was no longer wanted, and nothing of it was delivered.
        eventually("tile 9 dropped", || s.stats().dropped == 1);
        let st = s.stats();
        assert_eq!(st.cancelled_in_flight, 1, "{st:?}");
        assert!(s.drain().is_empty());
        // Tile 2's retry never ran.
        assert_eq!(
            src.attempts.lock().unwrap()[&TileKey::new(5, 2, 0)].len(),
            1
        );
    }

    #[test]
    fn ancestors_load_before_descendants_of_equal_priority() {
        let src = Arc::new(Recorder {
            order: Mutex::new(Vec::new()),
            gate: Mutex::new(false),
            started: AtomicUsize::new(0),
        });
        let s = Scheduler::new(Arc::clone(&src), 1);
        let blocker = TileRequest {
            key: TileKey::new(2, 0, 0),
            priority: 100.0,
        };
        s.submit(&[blocker]);
        while src.started.load(Ordering::SeqCst) == 0 {
            std::thread::sleep(Duration::from_millis(1));
        }
        let at = |level: u8| TileRequest {
            key: TileKey::new(level, 0, 0),
            priority: 1.0,
        };
        s.submit(&[blocker, at(7), at(4), at(6), at(5)]);
        *src.gate.lock().unwrap() = true;
        let _ = collect(&s, 5);
        let levels: Vec<u8> = src
            .order
            .lock()
            .unwrap()
            .iter()
            .map(|k| k.level())
            .collect();
        assert_eq!(levels, vec![2, 4, 5, 6, 7]);
    }

    #[test]
    fn a_delivered_tile_is_not_loaded_again_before_it_is_collected() {
        let src = Arc::new(Recorder {
            order: Mutex::new(Vec::new()),
            gate: Mutex::new(true),
            started: AtomicUsize::new(0),
        });
        let s = Scheduler::new(Arc::clone(&src), 2);
        s.submit(&[req(3, 1.0)]);
        eventually("loaded", || s.stats().loaded == 1);
        // The consumer has not drained yet and still lists the tile: no second load.
        for _ in 0..5 {
            s.submit(&[req(3, 1.0)]);
            std::thread::sleep(Duration::from_millis(20));
        }
        assert_eq!(s.stats().started, 1);
        assert_eq!(s.drain().len(), 1);
        // Collected: asking again is the consumer's decision and is honoured.
        s.submit(&[req(3, 1.0)]);
        eventually("loaded again", || s.stats().loaded == 2);
    }
}
