//! How many threads lgi's parallel work runs on: rayon's global pool by default
//! (`RAYON_NUM_THREADS`, else one per core), or lgi's own pool after `set_num_threads(n)`.
//! A pool of its own, rather than rayon's global one, because the global pool's size is fixed
//! by the first parallel call, which an import or an unpickled model may already have made.

use crate::convert::count;
use crate::error::input_error;
use pyo3::prelude::*;
use std::sync::mpsc::RecvTimeoutError;
use std::sync::{Arc, Mutex, RwLock};
use std::time::Duration;

/// The most threads `set_num_threads` accepts (a typo like 10**6 must not spawn a million).
pub const MAX_THREADS: usize = 1024;

/// lgi's own pool; `None`: rayon's global pool.
static POOL: RwLock<Option<Arc<rayon::ThreadPool>>> = RwLock::new(None);

fn current() -> Option<Arc<rayon::ThreadPool>> {
    // A poisoned lock only means a panic elsewhere while holding it: the value is still whole.
    POOL.read().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Runs `work` with the GIL released on the pool in force (the one `set_num_threads` made, or
/// rayon's global pool). Every heavy call of the binding goes through here.
pub fn detach<T: Send>(py: Python<'_>, work: impl FnOnce() -> T + Send) -> T {
    match current() {
        None => py.detach(work),
        Some(pool) => py.detach(move || pool.install(work)),
    }
}

/// [`detach`] for work that reports progress: on lgi's own pool the work runs off the calling
/// thread, where Python cannot see signals, so the calling thread waits by checking them
/// (every 20 ms) and puts a raised one (Ctrl-C: `KeyboardInterrupt`) in `interrupt`, which the
/// work's progress hook takes and stops with. On rayon's global pool the work runs on the
/// calling thread and its hook checks signals itself.
pub fn detach_watching<T: Send>(
    py: Python<'_>,
    interrupt: &Mutex<Option<PyErr>>,
    work: impl FnOnce() -> T + Send,
) -> T {
    let Some(pool) = current() else {
        return py.detach(work);
    };
    py.detach(move || {
        std::thread::scope(|s| {
            let (done, finished) = std::sync::mpsc::channel::<()>();
            let worker = s.spawn(move || {
                // Dropped when the work returns or unwinds: the wait below ends either way.
                let _done = done;
                pool.install(work)
            });
            while let Err(RecvTimeoutError::Timeout) = finished.recv_timeout(WATCH) {
                if let Err(e) = Python::attach(|py| py.check_signals()) {
                    *interrupt.lock().unwrap_or_else(|e| e.into_inner()) = Some(e);
                }
            }
            match worker.join() {
                Ok(value) => value,
                // The work's own unwinding (a stopped solve's private payload) goes on up.
                Err(payload) => std::panic::resume_unwind(payload),
            }
        })
    })
}

/// How often [`detach_watching`] checks for signals.
const WATCH: Duration = Duration::from_millis(20);

/// `lgi.set_num_threads(n)`: lgi's parallel work (build, load and unpickling, solve, the
/// baselines) runs on a pool of `n` threads from the next call on; None returns to rayon's
/// global pool. Calling it again replaces the pool (calls already running finish on theirs).
#[pyfunction]
#[pyo3(signature = (n))]
pub fn set_num_threads(n: Option<&Bound<'_, PyAny>>) -> PyResult<()> {
    let pool = match n {
        None => None,
        Some(n) => {
            let n = count(n, "set_num_threads: n")?;
            if !(1..=MAX_THREADS).contains(&n) {
                return Err(input_error(format!(
                    "set_num_threads: n must be from 1 to {MAX_THREADS} threads (or None for \
                     the default), got {n}"
                )));
            }
            if current().is_some_and(|p| p.current_num_threads() == n) {
                return Ok(());
            }
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .thread_name(|i| format!("lgi-{i}"))
                .build()
                .map_err(|e| {
                    input_error(format!("set_num_threads: cannot start {n} threads: {e}"))
                })?;
            Some(Arc::new(pool))
        }
    };
    *POOL.write().unwrap_or_else(|e| e.into_inner()) = pool;
    Ok(())
}

/// `lgi.get_num_threads()`: the number of threads lgi's parallel work runs on now.
#[pyfunction]
pub fn get_num_threads() -> usize {
    match current() {
        Some(pool) => pool.current_num_threads(),
        None => rayon::current_num_threads(),
    }
}
