//! Documented limits (issue #14): sizes checked before anything is allocated, and the ranges
//! beyond which a value cannot be sane (its derived quantities overflow or lose all precision).
//! Every check names the config key; the CLI renames keys to flags, readers add the file.
//!
//! | limit | value | why |
//! |---|---|---|
//! | [`MAX_AGENTS`] | 1 000 000 | perception and forces are `O(N·K)` per step: hours per step beyond |
//! | [`MAX_GRID_CELLS`] | 16 777 216 (4096²) | clip fields are `frames × cells` f64 arrays |
//! | [`MAX_STEPS`] | 100 000 000 | a run's frames; streamed outputs are also checked against the disk |
//! | [`MAX_RUNS`] | 10 000 | repetitions of one run: seeds, replicas, repeats, starts (each a whole run) |
//! | [`MAX_ITERATIONS`] | 1 000 000 | iterations of an optimiser or solver: epochs, sweeps, evaluations |
//! | [`MAX_SECONDS`] | 1e6 s (11.6 days) | a simulated duration; with the frame rate, bounded by [`MAX_STEPS`] |
//! | [`FPS_RANGE`] | 1e-3 ..= 1e6 | Δt = 1/fps multiplies every speed; outside, positions overflow or stall |
//! | [`MAX_COORD`] | 1e9 BL | squared distances stay far from f64 overflow (1e308) and f32 (3e38) |
//! | [`MAX_DENSITY`] | 1e3 agents/BL² | counts (density × cell area) fit a `usize` |
//! | [`MAX_SPEED`] | 1e6 BL/s | a speed × Δt stays within [`MAX_COORD`] over any run |
//! | memory | the machine's available memory (`/proc/meminfo` `MemAvailable`, `RLIMIT_AS`, and `HERDFIT_MEMORY_LIMIT` bytes when set) | an estimate above it is refused with both figures |
//! | disk | the free space of the output's file system (`statvfs`) | a streamed output larger than it is refused up front |

use crate::error::{Error, Result};
use std::path::Path;

/// Most agents in one run.
pub const MAX_AGENTS: usize = 1_000_000;
/// Most cells in one grid.
pub const MAX_GRID_CELLS: usize = 1 << 24;
/// Most steps (frames) in one run.
pub const MAX_STEPS: usize = 100_000_000;
/// Most repetitions of one run (seeds averaged over, replicas, timing repeats, starts).
pub const MAX_RUNS: usize = 10_000;
/// Most iterations of an optimiser or a solver (epochs, sweeps, evaluations).
pub const MAX_ITERATIONS: usize = 1_000_000;
/// Longest simulated duration (seconds).
pub const MAX_SECONDS: f64 = 1e6;
/// Frame rates accepted (frames per second).
pub const FPS_RANGE: (f64, f64) = (1e-3, 1e6);
/// Largest |coordinate| (body lengths) accepted in an input.
pub const MAX_COORD: f64 = 1e9;
/// Largest density (agents/BL²; also bounds a direction variance) accepted in clip fields: far
/// above packing (a body covers ≈ 0.3 BL²), low enough that counts from it fit any cell.
pub const MAX_DENSITY: f64 = 1e3;
/// Largest speed (BL/s) accepted in an input.
pub const MAX_SPEED: f64 = 1e6;

/// A number as a user typed it: shortest round trip, in exponent form when very large or small.
pub fn show(v: f64) -> String {
    if v != 0.0 && v.is_finite() && !(1e-4..1e15).contains(&v.abs()) {
        format!("{v:e}")
    } else {
        format!("{v}")
    }
}

/// The words of every finiteness error: "NaN is not a finite number".
pub fn not_finite(v: f64) -> String {
    format!("{} is not a finite number", show(v))
}

/// A finite `value` (the one wording of [`not_finite`]).
pub fn check_finite(key: &str, value: f64) -> Result<()> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(Error::config(key, not_finite(value)))
    }
}

/// A finite `value` within `lo..=hi` (`unit` after the range, may be empty).
pub fn check_range(key: &str, value: f64, lo: f64, hi: f64, unit: &str) -> Result<()> {
    check_finite(key, value)?;
    if !(lo..=hi).contains(&value) {
        let unit = if unit.is_empty() {
            String::new()
        } else {
            format!(" {unit}")
        };
        return Err(Error::config(
            key,
            format!(
                "{} is outside {}..={}{unit}",
                show(value),
                show(lo),
                show(hi)
            ),
        ));
    }
    Ok(())
}

/// `key = value` within `lo..=hi` (finite), as an [`Error::Invalid`] whose message starts with
/// the key (`"noise = 1e300 is outside 0..=100"`): the form of the configs that the CLI renames
/// to flags by that prefix.
pub fn within(key: &str, value: f64, lo: f64, hi: f64) -> Result<()> {
    if !value.is_finite() {
        return Err(Error::invalid(format!("{key} = {}", not_finite(value))));
    }
    if !(lo..=hi).contains(&value) {
        return Err(Error::invalid(format!(
            "{key} = {} is outside {}..={}",
            show(value),
            show(lo),
            show(hi)
        )));
    }
    Ok(())
}

/// Serde for an `f64` where ±inf means something (`guidance_scale = inf`): written as the strings
/// `"inf"`/`"-inf"` — JSON has no infinity, and serde_json writes it as `null`, which reads back
/// as nothing (issue #47) — and read from a number or those strings.
pub mod infinite_ok {
    use serde::{de::Error as _, Deserialize};

    pub fn serialize<S: serde::Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
        match *v {
            f64::INFINITY => s.serialize_str("inf"),
            f64::NEG_INFINITY => s.serialize_str("-inf"),
            x => s.serialize_f64(x),
        }
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum V {
            N(f64),
            S(String),
        }
        match V::deserialize(d)? {
            V::N(x) => Ok(x),
            V::S(s) if s == "inf" => Ok(f64::INFINITY),
            V::S(s) if s == "-inf" => Ok(f64::NEG_INFINITY),
            V::S(s) => Err(D::Error::custom(format!(
                "'{s}' is not a number (nor \"inf\")"
            ))),
        }
    }
}

/// A video scale of 2..=1000 pixels per body length, checked whether or not a video is asked for
/// (issue #47: 1e300 sized a frame that wrapped around and rendered for ever).
pub fn check_px_per_bl(v: f64) -> Result<()> {
    check_range("px_per_bl", v, 2.0, 1000.0, "pixels per body length")
}

/// `key` ≤ `max` (a count).
pub fn check_count(key: &str, value: usize, max: usize) -> Result<()> {
    if value > max {
        return Err(Error::config(
            key,
            format!("{value} is above the limit of {max}"),
        ));
    }
    Ok(())
}

/// A grid of `nx × ny` cells within [`MAX_GRID_CELLS`] (no overflow on the product).
pub fn check_grid(key: &str, nx: usize, ny: usize) -> Result<()> {
    match nx.checked_mul(ny) {
        Some(c) if c <= MAX_GRID_CELLS => Ok(()),
        _ => Err(Error::config(
            key,
            format!("{nx}×{ny} cells is above the limit of {MAX_GRID_CELLS} cells"),
        )),
    }
}

/// A frame rate within [`FPS_RANGE`].
pub fn check_fps(key: &str, fps: f64) -> Result<()> {
    let (lo, hi) = FPS_RANGE;
    if !(fps.is_finite() && (lo..=hi).contains(&fps)) {
        return Err(Error::config(
            key,
            format!(
                "{} is outside {lo}..={hi} frames per second (Δt = 1/fps)",
                show(fps)
            ),
        ));
    }
    Ok(())
}

/// The words of every magnitude error: "1e300 is beyond ±1e9".
pub fn beyond(v: f64, max: f64) -> String {
    format!("{} is beyond ±{}", show(v), show(max))
}

/// A finite value with |value| ≤ `max` (the wordings of [`not_finite`] and [`beyond`]).
pub fn check_magnitude(key: &str, value: f64, max: f64) -> Result<()> {
    check_finite(key, value)?;
    if value.abs() > max {
        return Err(Error::config(key, beyond(value, max)));
    }
    Ok(())
}

/// Memory available to this process (bytes): `MemAvailable` capped by `RLIMIT_AS` and by the
/// environment variable `HERDFIT_MEMORY_LIMIT` (bytes) when it is set (a shared machine's
/// budget; the parser fuzz runs under it).
pub fn available_memory() -> u64 {
    let mut avail = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("MemAvailable:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<u64>().ok())
        })
        .map_or(u64::MAX, |kb| kb.saturating_mul(1024));
    #[cfg(unix)]
    // SAFETY: getrlimit fills a plain struct.
    unsafe {
        let mut r: libc::rlimit = std::mem::zeroed();
        if libc::getrlimit(libc::RLIMIT_AS, &mut r) == 0 && r.rlim_cur != libc::RLIM_INFINITY {
            avail = avail.min(r.rlim_cur as u64);
        }
    }
    if let Some(cap) = std::env::var("HERDFIT_MEMORY_LIMIT")
        .ok()
        .and_then(|v| v.trim().parse::<u64>().ok())
    {
        avail = avail.min(cap);
    }
    avail
}

fn gib(b: f64) -> String {
    format!("{:.3} GiB", b / (1u64 << 30) as f64)
}

/// Refuses a run whose estimated memory `bytes` (for `what`) exceeds [`available_memory`].
pub fn check_memory(key: &str, what: &str, bytes: f64) -> Result<()> {
    let avail = available_memory() as f64;
    if !(bytes.is_finite() && bytes <= avail) {
        return Err(Error::config(
            key,
            format!(
                "{what} needs about {} of memory; {} is available",
                gib(bytes),
                gib(avail)
            ),
        ));
    }
    Ok(())
}

/// Refuses an output of about `bytes` that the free space of the file system holding `path`
/// cannot take.
pub fn check_disk(key: &str, path: &Path, bytes: f64) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let free = free_space(dir).unwrap_or(f64::INFINITY);
    if !(bytes.is_finite() && bytes <= free) {
        return Err(Error::config(
            key,
            format!(
                "the output {} would take about {}; {} is free there",
                path.display(),
                gib(bytes),
                gib(free)
            ),
        ));
    }
    Ok(())
}

#[cfg(unix)]
fn free_space(dir: &Path) -> Option<f64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).ok()?;
    // SAFETY: statvfs fills a plain struct from a NUL-terminated path.
    unsafe {
        let mut s: libc::statvfs = std::mem::zeroed();
        if libc::statvfs(c.as_ptr(), &mut s) != 0 {
            return None;
        }
        Some(s.f_bavail as f64 * s.f_frsize as f64)
    }
}

#[cfg(not(unix))]
fn free_space(_: &Path) -> Option<f64> {
    None
}

/// The finite-value guard of a run's state: `Err` naming the step, the agent and the likely
/// inputs when any position is NaN/inf or beyond [`MAX_COORD`].
pub fn check_state(
    step: usize,
    points: impl IntoIterator<Item = (f64, f64)>,
    likely: &str,
) -> Result<()> {
    for (i, (x, y)) in points.into_iter().enumerate() {
        if !(x.is_finite() && y.is_finite() && x.abs() <= MAX_COORD && y.abs() <= MAX_COORD) {
            return Err(Error::invalid(format!(
                "step {step}: agent {i} reached a non-finite or out-of-range position ({x}, {y}); \
                 check {likely}"
            )));
        }
    }
    Ok(())
}
