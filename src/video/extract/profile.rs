//! Stage timers of an extraction: with `HERDFIT_PROFILE` set, the wall time each stage spends in
//! its own thread, summed over the frames, is printed to stderr at the end (`stage: total ms over
//! calls`). Off, a timer is one relaxed load.

use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// 0: not yet read, 1: off, 2: on.
static STATE: AtomicU8 = AtomicU8::new(0);
/// (stage, summed time, calls) in order of first use.
static TIMES: Mutex<Vec<(&'static str, Duration, u32)>> = Mutex::new(Vec::new());

/// Whether `HERDFIT_PROFILE` is set.
pub(super) fn on() -> bool {
    match STATE.load(Ordering::Relaxed) {
        0 => {
            let on = std::env::var_os("HERDFIT_PROFILE").is_some();
            STATE.store(if on { 2 } else { 1 }, Ordering::Relaxed);
            on
        }
        s => s == 2,
    }
}

/// The start of a timed stage (none when profiling is off).
pub(super) fn start() -> Option<Instant> {
    on().then(Instant::now)
}

/// Adds the time since `t` to `stage`.
pub(super) fn stop(stage: &'static str, t: Option<Instant>) {
    let Some(t) = t else { return };
    let d = t.elapsed();
    let mut v = TIMES.lock().unwrap_or_else(|e| e.into_inner());
    match v.iter_mut().find(|s| s.0 == stage) {
        Some(s) => {
            s.1 += d;
            s.2 += 1;
        }
        None => v.push((stage, d, 1)),
    }
}

/// Runs `f` as the stage `stage`.
pub(super) fn time<T>(stage: &'static str, f: impl FnOnce() -> T) -> T {
    let t = start();
    let r = f();
    stop(stage, t);
    r
}

/// Prints and clears the stage times (with the extraction's wall time `total`).
pub(super) fn report(total: Duration) {
    if !on() {
        return;
    }
    let mut v = TIMES.lock().unwrap_or_else(|e| e.into_inner());
    eprintln!(
        "profile: extraction {:.1} ms wall",
        total.as_secs_f64() * 1e3
    );
    for (stage, d, n) in v.drain(..) {
        eprintln!(
            "profile: {stage:<28} {:>9.1} ms over {n:>5} calls ({:.2} ms each)",
            d.as_secs_f64() * 1e3,
            d.as_secs_f64() * 1e3 / n as f64
        );
    }
}
