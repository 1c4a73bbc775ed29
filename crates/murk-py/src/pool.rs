//! The rayon pools murk's work runs on, safe across `fork`.
//!
//! Every call runs inside a pool owned by this module (never rayon's global
//! pool, whose worker threads do not survive a `fork`: a child that touched
//! it would wait forever). Pools are kept per thread count and per process:
//! when the process id differs from the one the pools were built in (we are
//! in a forked child, e.g. a PyTorch DataLoader worker), the parent's pools
//! are abandoned — not dropped, since their threads and locks belong to the
//! parent — and fresh ones are built on first use.
//!
//! Thread count of a call: its `threads` argument, else
//! [`set_num_threads`], else the `MURK_NUM_THREADS` environment variable,
//! else the number of CPUs. Results do not depend on it (murk's draws are
//! seeded per fixed-size chunk).
//!
//! Polars (Parquet reading and writing) keeps a global pool of its own that
//! this module does not control; a forked child should not read or write
//! Parquet if its parent did.

use std::collections::HashMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use rayon::ThreadPool;

/// Pools of one process.
struct Pools {
    pid: u32,
    by_threads: HashMap<usize, Arc<ThreadPool>>,
}

static POOLS: Mutex<Option<Pools>> = Mutex::new(None);

/// Thread count set by `murk.set_num_threads` (0: not set).
static NUM_THREADS: AtomicUsize = AtomicUsize::new(0);

/// Sets the default thread count (0: back to the environment / CPU count).
pub fn set_num_threads(n: usize) {
    NUM_THREADS.store(n, Ordering::Relaxed);
}

/// The default thread count of a call.
pub fn num_threads() -> usize {
    let set = NUM_THREADS.load(Ordering::Relaxed);
    if set > 0 {
        return set;
    }
    std::env::var("MURK_NUM_THREADS")
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// The pool of `threads` workers of this process.
fn pool(threads: usize) -> Result<Arc<ThreadPool>, String> {
    let pid = std::process::id();
    // A poisoned lock only means a pool build panicked; the map is intact.
    let mut guard = POOLS.lock().unwrap_or_else(|e| e.into_inner());
    if guard.as_ref().is_some_and(|p| p.pid != pid) {
        // Forked child: the parent's pools have no threads here. Leak them.
        std::mem::forget(guard.take());
    }
    let pools = guard.get_or_insert_with(|| Pools {
        pid,
        by_threads: HashMap::new(),
    });
    if let Some(p) = pools.by_threads.get(&threads) {
        return Ok(p.clone());
    }
    let p = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("murk-{i}"))
        .build()
        .map_err(|e| format!("cannot start {threads} worker threads: {e}"))?;
    let p = Arc::new(p);
    pools.by_threads.insert(threads, p.clone());
    Ok(p)
}

/// Runs `f` on a pool of `threads` workers (`None`: [`num_threads`]).
pub fn run<R: Send>(threads: Option<usize>, f: impl FnOnce() -> R + Send) -> Result<R, String> {
    let n = threads.unwrap_or_else(num_threads).max(1);
    Ok(pool(n)?.install(f))
}
