//! The fuzz engine of issue #14: a heap-counting allocator, mutations of a valid file (truncation,
//! byte flips, tokens replaced by huge numbers / NaN / wrong types, lines dropped or repeated,
//! JSON values replaced by wrong types or removed, arrays grown) and arbitrary bytes, run by
//! proptest's `TestRunner` with a fixed seed.
//!
//! A target passes a case when its parser returns `Ok` or an `Err` whose message names one of the
//! files it read, does not panic (proptest reports a panic as a failure, shrunk), and holds at
//! most [`HEAP_CAP`] more heap bytes at any moment than before the call: the memory limit the
//! fuzz sets through `HERDFIT_MEMORY_LIMIT` (`herdfit::limits::available_memory`), plus slack for
//! what a parser keeps of a file of a few KiB. A parser that allocates what a file's header claims
//! before checking it against the limits fails here.

use proptest::prelude::*;
use proptest::sample::Index;
use proptest::test_runner::{Config, RngAlgorithm, TestCaseError, TestRng, TestRunner};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

/// The memory limit the fuzz runs under (bytes), set as `HERDFIT_MEMORY_LIMIT`.
pub const MEMORY_LIMIT: u64 = 256 << 20;
/// The most heap a case may hold above what it started with: the limit plus 64 MiB of slack.
pub const HEAP_CAP: usize = (MEMORY_LIMIT as usize) + (64 << 20);

thread_local! {
    static LIVE: Cell<isize> = const { Cell::new(0) };
    static PEAK: Cell<isize> = const { Cell::new(0) };
}

/// `System` with per-thread live/peak heap counts (a parse runs on the test's own thread).
pub struct Counting;

fn add(n: isize) {
    let _ = LIVE.try_with(|l| {
        let v = l.get() + n;
        l.set(v);
        let _ = PEAK.try_with(|p| {
            if v > p.get() {
                p.set(v)
            }
        });
    });
}

// SAFETY: every call is forwarded to `System`; the counters are const-initialised thread locals
// with no destructor (they never allocate).
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, l: Layout) -> *mut u8 {
        let p = System.alloc(l);
        if !p.is_null() {
            add(l.size() as isize);
        }
        p
    }
    unsafe fn alloc_zeroed(&self, l: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(l);
        if !p.is_null() {
            add(l.size() as isize);
        }
        p
    }
    unsafe fn dealloc(&self, p: *mut u8, l: Layout) {
        System.dealloc(p, l);
        add(-(l.size() as isize));
    }
    unsafe fn realloc(&self, p: *mut u8, l: Layout, n: usize) -> *mut u8 {
        let q = System.realloc(p, l, n);
        if !q.is_null() {
            add(n as isize - l.size() as isize);
        }
        q
    }
}

/// Runs `f` and returns its result with the most heap (bytes) it held above the start.
pub fn measured<T>(f: impl FnOnce() -> T) -> (T, usize) {
    let start = LIVE.with(|l| l.get());
    PEAK.with(|p| p.set(start));
    let r = f();
    let peak = PEAK.with(|p| p.get());
    (r, (peak - start).max(0) as usize)
}

/// Cases per parser: `HERDFIT_FUZZ_CASES`, default 10,000. With `HERDFIT_FUZZ_CPU_SECONDS` this
/// is the size of one round (see [`cpu_budget`]).
pub fn cases() -> u32 {
    std::env::var("HERDFIT_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10_000)
}

/// The long-run mode: `HERDFIT_FUZZ_CPU_SECONDS=S` repeats rounds of [`cases`] cases, round r
/// seeded with r (round 0 is the default run), until the test's thread has used S seconds of
/// CPU. CPU time rather than wall time, so a run on a shared machine still fuzzes for S seconds.
pub fn cpu_budget() -> Option<f64> {
    std::env::var("HERDFIT_FUZZ_CPU_SECONDS")
        .ok()
        .and_then(|v| v.parse().ok())
}

/// CPU seconds used by the calling thread (`CLOCK_THREAD_CPUTIME_ID`).
pub fn thread_cpu_seconds() -> f64 {
    let mut t = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `t` is a valid, writable timespec; the clock id is a constant the kernel knows.
    let rc = unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    assert_eq!(rc, 0, "clock_gettime(CLOCK_THREAD_CPUTIME_ID)");
    t.tv_sec as f64 + t.tv_nsec as f64 * 1e-9
}

/// The seed of round `r`: round 0 is proptest's deterministic default, so the default run is
/// the first round of every long run.
fn round_rng(r: u64) -> TestRng {
    if r == 0 {
        return TestRng::deterministic_rng(RngAlgorithm::ChaCha);
    }
    let mut seed = [0u8; 32];
    seed[..8].copy_from_slice(&r.to_le_bytes());
    seed[8..16].copy_from_slice(b"herdfuzz");
    TestRng::from_seed(RngAlgorithm::ChaCha, &seed)
}

/// Replacement tokens: huge, tiny, negative, non-finite, out-of-range integers, wrong types.
pub const TOKENS: &[&str] = &[
    "NaN",
    "nan",
    "inf",
    "-inf",
    "1e300",
    "-1e300",
    "1e-300",
    "1e999",
    "0",
    "-0",
    "-1",
    "1",
    "4096",
    "1000000",
    "1e9",
    "4294967296",
    "18446744073709551615",
    "18446744073709551616",
    "-9223372036854775809",
    "0.5",
    "\"\"",
    "\"x\"",
    "null",
    "true",
    "[]",
    "{}",
    "[[]]",
    ",",
    "\n",
    "",
    "#",
    "é",
    "\u{0}",
];

/// One mutation of a file's bytes.
#[derive(Clone, Debug)]
pub enum Op {
    /// Keep only the first part.
    Truncate(Index),
    /// XOR one byte.
    Flip(Index, u8),
    /// Replace the token (a run of non-separator bytes) around a position.
    Token(Index, usize),
    /// Insert a token at a position.
    Insert(Index, usize),
    /// Drop one line.
    DropLine(Index),
    /// Repeat one line `n` times.
    RepeatLine(Index, u8),
    /// A JSON value (any node, by DFS order) edited (see [`json_edit`]).
    Json(Index, u8),
}

fn op() -> impl Strategy<Value = Op> {
    let tok = 0..TOKENS.len();
    prop_oneof![
        any::<Index>().prop_map(Op::Truncate),
        (any::<Index>(), 1..=255u8).prop_map(|(i, b)| Op::Flip(i, b)),
        (any::<Index>(), tok.clone()).prop_map(|(i, t)| Op::Token(i, t)),
        (any::<Index>(), tok).prop_map(|(i, t)| Op::Insert(i, t)),
        any::<Index>().prop_map(Op::DropLine),
        (any::<Index>(), 2..=60u8).prop_map(|(i, n)| Op::RepeatLine(i, n)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, e)| Op::Json(i, e)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, e)| Op::Json(i, e)),
        (any::<Index>(), any::<u8>()).prop_map(|(i, e)| Op::Json(i, e)),
    ]
}

/// One case: which file of the target, and either arbitrary bytes or mutations of its seed.
#[derive(Clone, Debug)]
pub enum Case {
    Bytes(Index, Vec<u8>),
    Mutate(Index, Vec<Op>),
}

pub fn case() -> impl Strategy<Value = Case> {
    prop_oneof![
        1 => (any::<Index>(), prop::collection::vec(any::<u8>(), 0..400))
            .prop_map(|(f, b)| Case::Bytes(f, b)),
        5 => (any::<Index>(), prop::collection::vec(op(), 1..4))
            .prop_map(|(f, o)| Case::Mutate(f, o)),
    ]
}

fn is_sep(b: u8) -> bool {
    b.is_ascii_whitespace() || b",:;[]{}()\"'".contains(&b)
}

fn token_span(b: &[u8], at: usize) -> (usize, usize) {
    let mut s = at;
    while s > 0 && !is_sep(b[s - 1]) {
        s -= 1;
    }
    let mut e = at;
    while e < b.len() && !is_sep(b[e]) {
        e += 1;
    }
    (s, e)
}

fn line_spans(b: &[u8]) -> Vec<(usize, usize)> {
    let mut v = Vec::new();
    let mut s = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            v.push((s, i + 1));
            s = i + 1;
        }
    }
    if s < b.len() {
        v.push((s, b.len()));
    }
    v
}

/// Every node of a JSON value as a JSON pointer, in DFS order.
fn pointers(v: &serde_json::Value, at: String, out: &mut Vec<String>) {
    match v {
        serde_json::Value::Object(m) => {
            for (k, c) in m {
                pointers(
                    c,
                    format!("{at}/{}", k.replace('~', "~0").replace('/', "~1")),
                    out,
                );
            }
        }
        serde_json::Value::Array(a) => {
            for (i, c) in a.iter().enumerate() {
                pointers(c, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
    out.push(at);
}

/// Edits the JSON node `ptr` of `root`: a wrong value, removed, or (arrays) grown.
fn json_edit(root: &mut serde_json::Value, ptr: &str, e: u8) {
    use serde_json::json;
    let wrong = [
        json!(1e300),
        json!(-1e300),
        json!(1e-300),
        json!(-1),
        json!(0),
        json!(u64::MAX),
        json!(i64::MIN),
        json!(4096),
        json!(1_000_000_000u64),
        json!(0.5),
        json!("x"),
        json!("NaN"),
        json!(null),
        json!(true),
        json!([]),
        json!({}),
        json!([1e300, -1e300]),
        json!({"schema": 1}),
    ];
    let n = wrong.len() as u8;
    let e = e % (n + 3);
    if e < n {
        if let Some(slot) = root.pointer_mut(ptr) {
            *slot = wrong[e as usize].clone();
        }
        return;
    }
    if e == n + 2 {
        // Grow an array: its first element repeated 200 times.
        if let Some(serde_json::Value::Array(a)) = root.pointer_mut(ptr) {
            if let Some(first) = a.first().cloned() {
                a.extend(std::iter::repeat_n(first, 200));
            }
        }
        return;
    }
    // Remove the node from its parent (n, n + 1).
    let Some((parent, last)) = ptr.rsplit_once('/') else {
        return;
    };
    match root.pointer_mut(parent) {
        Some(serde_json::Value::Object(m)) => {
            m.remove(&last.replace("~1", "/").replace("~0", "~"));
        }
        Some(serde_json::Value::Array(a)) => {
            if let Ok(i) = last.parse::<usize>() {
                if i < a.len() {
                    a.remove(i);
                }
            }
        }
        _ => {}
    }
}

/// `seed` after the mutations `ops`.
pub fn mutate(seed: &[u8], ops: &[Op]) -> Vec<u8> {
    let mut b = seed.to_vec();
    for o in ops {
        match o {
            Op::Truncate(i) => b.truncate(i.index(b.len() + 1)),
            Op::Flip(i, x) if !b.is_empty() => {
                let k = i.index(b.len());
                b[k] ^= x;
            }
            Op::Token(i, t) if !b.is_empty() => {
                let (s, e) = token_span(&b, i.index(b.len()));
                b.splice(s..e, TOKENS[*t].bytes());
            }
            Op::Insert(i, t) => {
                let k = i.index(b.len() + 1);
                b.splice(k..k, TOKENS[*t].bytes());
            }
            Op::DropLine(i) => {
                let l = line_spans(&b);
                if !l.is_empty() {
                    let (s, e) = l[i.index(l.len())];
                    b.drain(s..e);
                }
            }
            Op::RepeatLine(i, n) => {
                let l = line_spans(&b);
                if !l.is_empty() {
                    let (s, e) = l[i.index(l.len())];
                    let line = b[s..e].to_vec();
                    for _ in 1..*n {
                        b.splice(e..e, line.iter().copied());
                    }
                }
            }
            Op::Json(i, e) => {
                if let Ok(mut v) = serde_json::from_slice::<serde_json::Value>(&b) {
                    let mut ps = Vec::new();
                    pointers(&v, String::new(), &mut ps);
                    json_edit(&mut v, &ps[i.index(ps.len())], *e);
                    b = serde_json::to_vec_pretty(&v).expect("serialisable");
                }
            }
            _ => {}
        }
    }
    b
}

/// What a parser returns to the fuzz: `Ok` (after its own finite-value checks of the result) or
/// the library's error.
pub type Parse = Box<dyn Fn(&Path) -> herdfit::Result<()>>;

/// A parser under fuzz: the files it reads (name in its folder, valid bytes) and the call.
pub struct Target {
    pub name: &'static str,
    pub files: Vec<(String, Vec<u8>)>,
    pub parse: Parse,
}

/// Sets the fuzz's memory limit for this process (before any case).
pub fn limit_memory() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| std::env::set_var("HERDFIT_MEMORY_LIMIT", MEMORY_LIMIT.to_string()));
}

/// Runs [`cases`] cases of `t` (fixed seed) and panics with the shrunk failing case, if any.
pub fn fuzz(t: Target) {
    limit_memory();
    // Cases rewrite the same files thousands of times: on a memory file system when there is one
    // (ext4 flushes a truncated-and-rewritten file on close, which makes a case 10× slower).
    let shm = Path::new("/dev/shm");
    let dir = if shm.is_dir() {
        tempfile::tempdir_in(shm)
    } else {
        tempfile::tempdir()
    }
    .expect("temp dir");
    let valid = |d: &Path| {
        for (n, b) in &t.files {
            let p = d.join(n);
            std::fs::create_dir_all(p.parent().unwrap()).expect("seed folder");
            std::fs::write(p, b).expect("write seed");
        }
    };
    // The seeds themselves parse.
    valid(dir.path());
    if let Err(e) = (t.parse)(dir.path()) {
        panic!("{}: the valid seed does not parse: {e}", t.name);
    }
    let names: Vec<String> = t.files.iter().map(|(n, _)| n.clone()).collect();
    let config = Config {
        cases: cases(),
        failure_persistence: None,
        max_shrink_iters: 2000,
        ..Config::default()
    };
    let start = std::time::Instant::now();
    let cpu0 = thread_cpu_seconds();
    let (oks, errs) = (Cell::new(0u64), Cell::new(0u64));
    let mut round = 0u64;
    loop {
        let mut runner = TestRunner::new_with_rng(config.clone(), round_rng(round));
        let res = runner.run(&case(), |c| {
            valid(dir.path());
            let (k, bytes) = match &c {
                Case::Bytes(f, b) => (f.index(names.len()), b.clone()),
                Case::Mutate(f, ops) => {
                    let k = f.index(names.len());
                    (k, mutate(&t.files[k].1, ops))
                }
            };
            std::fs::write(dir.path().join(&names[k]), &bytes).expect("write case");
            let (r, peak) = measured(|| (t.parse)(dir.path()));
            if peak > HEAP_CAP {
                return Err(TestCaseError::fail(format!(
                    "{}: held {peak} bytes of heap (cap {HEAP_CAP}); result {r:?}",
                    names[k]
                )));
            }
            if r.is_ok() {
                oks.set(oks.get() + 1);
            }
            if let Err(e) = r {
                errs.set(errs.get() + 1);
                let m = e.to_string();
                let d = dir.path().display().to_string();
                if !m.contains(&d) && !names.iter().any(|n| m.contains(n.as_str())) {
                    return Err(TestCaseError::fail(format!(
                        "{}: the error names no file: {m}",
                        names[k]
                    )));
                }
            }
            Ok(())
        });
        if let Err(e) = res {
            panic!("{} (round {round}): {e}", t.name);
        }
        round += 1;
        match cpu_budget() {
            Some(s) if thread_cpu_seconds() - cpu0 < s => {}
            _ => break,
        }
    }
    eprintln!(
        "fuzz {}: {} cases in {round} round(s), {:.1} s wall, {:.1} s CPU ({} Ok, {} Err)",
        t.name,
        round * u64::from(cases()),
        start.elapsed().as_secs_f64(),
        thread_cpu_seconds() - cpu0,
        oks.get(),
        errs.get()
    );
    // The mutations reach past the first check: some cases are still valid files.
    assert!(oks.get() > 0, "{}: no mutated case parsed", t.name);
}
