//! The whole-CLI engine (issue #47): from a command table (clap), a program and one or more
//! working invocations per verb (the baselines), it generates the hostile cases and checks every
//! promise on each — one `error:` line naming the file or flag, a non-zero exit, no panic, every
//! input byte-identical and nothing left behind (hidden files included); or, where a value may be
//! legitimate (−1 degrees, 10^9 as a seed), a clean run with finite outputs and nothing hidden
//! left. It knows nothing of herdfit's verbs: a new verb or flag is picked up from the table.
//!
//! Cases, per baseline:
//! - every output onto every input, every input's sidecar, every other output, and (for a tracks
//!   output) a name whose sidecar is an input;
//! - every output onto a device, a symbolic link, a dangling link, a FIFO, an existing folder (or
//!   file, for folder outputs) and a missing folder;
//! - all outputs on a full file system (a tmpfs, when running as root; else skipped with a message);
//!
//! and per numeric flag of each verb: 1e300, NaN, −1 and inf (floating-point), 10^9, 1e300, NaN
//! and −1 (integers), the same in the first component of a compound value (`DX,DY`, `NXxNY`, …).

use super::table::{Role, Value, Verb};
use std::collections::BTreeMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// What is tested: a program, its command table, working invocations, and the folder every case
/// starts from (copied).
pub struct Subject {
    pub program: PathBuf,
    pub verbs: Vec<Verb>,
    /// `(verb words joined by spaces, arguments)`.
    pub baselines: Vec<(String, Vec<String>)>,
    pub fixture: PathBuf,
    /// Verbs whose baselines are too long to run in this suite (their refusals still are): the
    /// tmpfs of their full-disk case gets this many bytes.
    pub long_verbs: Vec<(String, u64)>,
    /// Wall-time limit of one case.
    pub timeout: Duration,
}

/// What a case must do.
#[derive(Clone, Debug, PartialEq)]
pub enum Expect {
    /// Refuse: non-zero exit, one `error:` line containing every string of `names`, nothing changed.
    Refused(Vec<String>),
    /// Refuse as above, or run cleanly (exit 0, finite outputs, inputs unchanged, nothing hidden left).
    RefusedOrClean(Vec<String>),
}

/// What a case prepares in its folder before it runs.
#[derive(Clone, Debug)]
pub enum Setup {
    None,
    Symlink {
        link: String,
        to: String,
        real: bool,
    },
    Fifo(String),
    Folder(String),
    File(String),
    /// A tmpfs at `dir` of `bytes`, filled to the brim when `fill`.
    Tmpfs {
        dir: String,
        bytes: u64,
        fill: bool,
    },
}

#[derive(Clone, Debug)]
pub struct Case {
    pub kind: &'static str,
    pub label: String,
    pub args: Vec<String>,
    pub expect: Expect,
    pub setup: Setup,
    /// The baseline's outputs (to judge a clean run).
    pub baseline: usize,
    /// State folders (checkpoints) of the case: a run that fails after finishing an epoch keeps
    /// them so that it can be resumed; their contents may change on a refusal.
    pub state: Vec<String>,
}

/// The outcome of a suite.
#[derive(Default, Debug)]
pub struct Report {
    pub cases: usize,
    pub by_kind: BTreeMap<&'static str, usize>,
    pub accepted: usize,
    pub failures: Vec<String>,
    pub notes: Vec<String>,
    pub seconds: f64,
}

/// A baseline's run: its outputs (relative paths) with their JSON null counts, and total bytes.
#[derive(Clone, Debug, Default)]
pub struct Ran {
    pub ok: bool,
    pub outputs: BTreeMap<PathBuf, usize>,
    pub bytes: u64,
    pub seconds: f64,
}

// ---- Files ----

/// Every file and folder under `dir` (hidden ones included) with a hash of each file's bytes.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, u64> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        let Ok(rd) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in rd.flatten() {
            let p = e.path();
            let Ok(m) = std::fs::symlink_metadata(&p) else {
                continue;
            };
            let h = if m.is_dir() {
                stack.push(p.clone());
                0
            } else if m.is_file() {
                let mut s = std::collections::hash_map::DefaultHasher::new();
                std::fs::read(&p).unwrap_or_default().hash(&mut s);
                s.finish()
            } else {
                1 + m.len()
            };
            out.insert(p.strip_prefix(dir).unwrap().to_path_buf(), h);
        }
    }
    out
}

pub fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let p = e.path();
        let t = to.join(e.file_name());
        if p.is_dir() {
            copy_tree(&p, &t);
        } else {
            std::fs::copy(&p, &t).unwrap();
        }
    }
}

/// `NaN`/`inf` tokens in a text file, and the number of JSON `null`s.
fn text_problems(p: &Path) -> (Vec<String>, usize) {
    let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
    if !matches!(ext, "csv" | "json" | "txt" | "md") {
        return (Vec::new(), 0);
    }
    let mut t = std::fs::read_to_string(p).unwrap_or_default();
    if ext == "json" {
        // The strings "inf"/"-inf" are how a meaningful infinity is written (limits::infinite_ok:
        // `--guidance-scale inf`); a leaked non-finite number is a bare token or a null.
        t = t.replace("\"inf\"", "").replace("\"-inf\"", "");
    }
    let mut bad = Vec::new();
    for tok in t.split(|c: char| !(c.is_ascii_alphanumeric() || c == '.' || c == '-' || c == '+')) {
        let l = tok.trim_start_matches(['-', '+']).to_ascii_lowercase();
        if l == "nan" || l == "inf" || l == "infinity" {
            bad.push(tok.to_string());
        }
    }
    let nulls = if ext == "json" {
        t.matches("null").count()
    } else {
        0
    };
    (bad, nulls)
}

/// Non-finite floats in a glTF binary's float accessors.
fn glb_problems(p: &Path) -> Vec<String> {
    let Ok(b) = std::fs::read(p) else {
        return vec!["unreadable".into()];
    };
    let u32at = |i: usize| u32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]) as usize;
    if b.len() < 20 || &b[0..4] != b"glTF" {
        return vec!["not a glb".into()];
    }
    let jlen = u32at(12);
    let Ok(doc) = serde_json::from_slice::<serde_json::Value>(&b[20..20 + jlen]) else {
        return vec!["bad JSON chunk".into()];
    };
    let bin = 20 + jlen + 8;
    let mut bad = Vec::new();
    let views = doc["bufferViews"].as_array().cloned().unwrap_or_default();
    for (k, a) in doc["accessors"]
        .as_array()
        .cloned()
        .unwrap_or_default()
        .iter()
        .enumerate()
    {
        if a["componentType"] != 5126 {
            continue;
        }
        let width = match a["type"].as_str().unwrap_or("") {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            _ => 16,
        };
        let v = &views[a["bufferView"].as_u64().unwrap_or(0) as usize];
        let off = bin
            + v["byteOffset"].as_u64().unwrap_or(0) as usize
            + a["byteOffset"].as_u64().unwrap_or(0) as usize;
        let n = a["count"].as_u64().unwrap_or(0) as usize * width;
        for i in 0..n {
            let at = off + 4 * i;
            if at + 4 > b.len() {
                break;
            }
            let f = f32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]]);
            if !f.is_finite() {
                bad.push(format!("accessor {k}: {f}"));
                break;
            }
        }
    }
    bad
}

// ---- Running one invocation ----

struct Outcome {
    code: Option<i32>,
    stderr: String,
    seconds: f64,
    timed_out: bool,
}

fn run_in(subject: &Subject, dir: &Path, args: &[String]) -> Outcome {
    let t0 = Instant::now();
    let mut cmd = Command::new(&subject.program);
    cmd.args(args)
        .current_dir(dir)
        .env("RAYON_NUM_THREADS", "1")
        .env("HERDFIT_MEMORY_LIMIT", (4u64 << 30).to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    #[cfg(unix)]
    {
        use std::os::unix::process::CommandExt;
        // A verb that allocates what nobody checked dies here rather than taking the machine.
        unsafe {
            cmd.pre_exec(|| {
                let lim = libc::rlimit {
                    rlim_cur: 16 << 30,
                    rlim_max: 16 << 30,
                };
                libc::setrlimit(libc::RLIMIT_AS, &lim);
                Ok(())
            });
        }
    }
    let mut child = cmd.spawn().expect("the program runs");
    let mut err = child.stderr.take().unwrap();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        use std::io::Read;
        let _ = err.read_to_string(&mut s);
        s
    });
    let mut timed_out = false;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > subject.timeout {
            let _ = child.kill();
            timed_out = true;
            break child.wait().unwrap();
        }
        std::thread::sleep(Duration::from_millis(5));
    };
    Outcome {
        code: status.code(),
        stderr: reader.join().unwrap_or_default(),
        seconds: t0.elapsed().as_secs_f64(),
        timed_out,
    }
}

fn workdir(subject: &Subject) -> tempfile::TempDir {
    let t = tempfile::Builder::new()
        .prefix("herdfit-whole-cli-")
        .tempdir()
        .unwrap();
    copy_tree(&subject.fixture, t.path());
    t
}

/// Runs a baseline; its outputs are the files it adds.
pub fn run_baseline(subject: &Subject, args: &[String]) -> (Ran, String) {
    let t = workdir(subject);
    let before = snapshot(t.path());
    let o = run_in(subject, t.path(), args);
    let after = snapshot(t.path());
    let mut ran = Ran {
        ok: o.code == Some(0),
        seconds: o.seconds,
        ..Ran::default()
    };
    for p in after.keys().filter(|p| !before.contains_key(*p)) {
        let full = t.path().join(p);
        if full.is_file() {
            ran.bytes += std::fs::metadata(&full).map_or(0, |m| m.len());
            ran.outputs.insert(p.clone(), text_problems(&full).1);
        }
    }
    (ran, o.stderr)
}

// ---- Cases ----

/// The argument vector of a baseline with clap's indices of every argument's values.
struct Parsed {
    argv: Vec<String>,
    /// id → indices (into `argv`) of its values.
    at: BTreeMap<String, Vec<usize>>,
}

/// Parses `args` (the verb's words first) with clap (so that a baseline that does not parse is
/// reported) and finds where each argument's values stand: `--flag value` pairs, and positionals
/// in order (a many-valued positional takes every free token).
fn parse(cmd: &clap::Command, verb: &Verb, args: &[String]) -> Result<Parsed, String> {
    let mut full = vec!["prog".to_string()];
    full.extend(args.iter().cloned());
    cmd.clone()
        .try_get_matches_from(&full)
        .map_err(|e| e.to_string())?;
    let mut at: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    let mut free = Vec::new();
    let mut i = verb.words.len();
    while i < args.len() {
        let t = &args[i];
        if let Some(long) = t.strip_prefix("--") {
            let (name, inline) = match long.split_once('=') {
                Some((n, _)) => (n, true),
                None => (long, false),
            };
            let a = verb
                .args
                .iter()
                .find(|a| a.long.as_deref() == Some(name))
                .ok_or_else(|| format!("unknown flag {t}"))?;
            if a.takes_value && !inline {
                at.entry(a.id.clone()).or_default().push(i + 1);
                i += 2;
            } else {
                if inline {
                    at.entry(a.id.clone()).or_default().push(i);
                }
                i += 1;
            }
        } else {
            free.push(i);
            i += 1;
        }
    }
    let mut positionals: Vec<&super::table::Arg> =
        verb.args.iter().filter(|a| a.index.is_some()).collect();
    positionals.sort_by_key(|a| a.index);
    let mut k = 0;
    for a in positionals {
        if k >= free.len() {
            break;
        }
        if a.many {
            at.insert(a.id.clone(), free[k..].to_vec());
            k = free.len();
        } else {
            at.insert(a.id.clone(), vec![free[k]]);
            k += 1;
        }
    }
    Ok(Parsed {
        argv: args.to_vec(),
        at,
    })
}

fn with(argv: &[String], i: usize, v: &str) -> Vec<String> {
    let mut a = argv.to_vec();
    a[i] = v.to_string();
    a
}

fn ext_of(v: &str) -> String {
    Path::new(v)
        .extension()
        .map_or(String::new(), |e| format!(".{}", e.to_string_lossy()))
}

fn csv_sidecar(v: &str) -> Option<String> {
    v.ends_with(".csv")
        .then(|| format!("{}.json", &v[..v.len() - 4]))
}

/// The path-generating cases of one baseline.
fn path_cases(subject: &Subject, verb: &Verb, b: usize, p: &Parsed, out: &mut Vec<Case>) {
    let key = verb.key();
    let words = verb.words.len();
    let mut inputs: Vec<String> = Vec::new();
    let mut outputs: Vec<(String, usize, Role)> = Vec::new();
    for a in &verb.args {
        let Value::Path(role) = a.value else {
            continue;
        };
        for &i in p.at.get(&a.id).map(Vec::as_slice).unwrap_or(&[]) {
            let v = p.argv[i].clone();
            if role.output() {
                outputs.push((a.name(), i, role));
                continue;
            }
            match role {
                Role::InPrefix => {
                    for s in ["_data_meta.txt", "_data_frame.txt", "_data_cell.txt"] {
                        inputs.push(format!("{v}{s}"));
                    }
                }
                Role::InFileOrWord if !subject.fixture.join(&v).exists() => {}
                _ => {
                    if let Some(side) = csv_sidecar(&v) {
                        if subject.fixture.join(&side).exists() {
                            inputs.push(side);
                        }
                    }
                    inputs.push(v);
                }
            }
        }
    }
    inputs.sort();
    inputs.dedup();
    let push = |out: &mut Vec<Case>, kind, label: String, args, names: Vec<String>, setup| {
        out.push(Case {
            kind,
            label: format!("{key}: {label}"),
            args,
            expect: Expect::Refused(names),
            setup,
            baseline: b,
            state: Vec::new(),
        })
    };
    let _ = words;
    for (name, i, role) in &outputs {
        let v = p.argv[*i].clone();
        for q in &inputs {
            push(
                out,
                "onto an input",
                format!("{name} onto input {q}"),
                with(&p.argv, *i, q),
                vec![q.clone()],
                Setup::None,
            );
            let csv = format!("{}.csv", q.strip_suffix(".json").unwrap_or(q));
            if *role == Role::OutTracks && q.ends_with(".json") && !inputs.contains(&csv) {
                push(
                    out,
                    "onto an input",
                    format!("{name} {csv}, whose sidecar is input {q}"),
                    with(&p.argv, *i, &csv),
                    vec![q.clone()],
                    Setup::None,
                );
            }
        }
        for (other, j, _) in &outputs {
            if j != i {
                push(
                    out,
                    "onto another output",
                    format!("{name} onto {other} {}", p.argv[*j]),
                    with(&p.argv, *i, &p.argv[*j]),
                    vec![p.argv[*j].clone()],
                    Setup::None,
                );
            }
        }
        let e = if role.folder() {
            String::new()
        } else {
            ext_of(&v)
        };
        let mut targets: Vec<(String, Setup)> = vec![
            ("/dev/null".into(), Setup::None),
            (
                format!("link{e}"),
                Setup::Symlink {
                    link: format!("link{e}"),
                    to: format!("real{e}"),
                    real: true,
                },
            ),
            (
                format!("dangling{e}"),
                Setup::Symlink {
                    link: format!("dangling{e}"),
                    to: format!("nowhere{e}"),
                    real: false,
                },
            ),
            (format!("fifo{e}"), Setup::Fifo(format!("fifo{e}"))),
        ];
        if role.folder() {
            targets.push(("afile".into(), Setup::File("afile".into())));
            if matches!(role, Role::OutDir | Role::OutDirAll) {
                targets.push(("home".into(), Setup::Folder("home".into())));
            }
        } else {
            targets.push((format!("adir{e}"), Setup::Folder(format!("adir{e}"))));
        }
        if matches!(role, Role::OutFile | Role::OutTracks | Role::OutDir) {
            targets.push((format!("missing/x{e}"), Setup::None));
        }
        for (t, setup) in targets {
            push(
                out,
                "onto a hostile target",
                format!("{name} onto {t}"),
                with(&p.argv, *i, &t),
                vec![t.clone()],
                setup,
            );
        }
    }
    // A full file system: every output moved onto a small tmpfs.
    if outputs.iter().any(|(_, i, _)| p.argv[*i] == "-") || outputs.is_empty() {
        return;
    }
    let mut argv = p.argv.clone();
    for (_, i, _) in &outputs {
        let name = Path::new(&argv[*i])
            .file_name()
            .map_or("x".into(), |n| n.to_string_lossy().into_owned());
        argv[*i] = format!("full/{name}");
    }
    let long = subject
        .long_verbs
        .iter()
        .find(|(k, _)| *k == key)
        .map(|(_, b)| *b);
    let mut sizes = vec![(64 * 1024, true)];
    if let Some(bytes) = long {
        sizes.push((bytes, false));
    } else {
        // Resolved from the baseline's run: half of what its outputs take (dropped when they
        // take under 16 KiB, which a tmpfs of whole pages may hold).
        sizes.push((0, false));
    }
    for (bytes, fill) in sizes {
        out.push(Case {
            kind: "full disk",
            label: format!(
                "{key}: outputs on a {} tmpfs",
                if fill { "full" } else { "half-size" }
            ),
            args: argv.clone(),
            expect: Expect::Refused(Vec::new()),
            setup: Setup::Tmpfs {
                dir: "full".into(),
                bytes,
                fill,
            },
            baseline: b,
            state: Vec::new(),
        });
    }
}

/// Hostile values of a number (`float` or integer).
fn hostile(float: bool) -> Vec<(&'static str, bool)> {
    // (value, may be accepted)
    if float {
        // 1e300 is no physical quantity: refused by every flag's range (or, where huge means
        // "everywhere", accepted like inf).
        vec![
            ("1e300", false),
            ("NaN", false),
            ("-1", true),
            ("inf", false),
        ]
    } else {
        vec![
            ("1000000000", true),
            ("1e300", false),
            ("NaN", false),
            ("-1", false),
        ]
    }
}

/// The first number in a compound value replaced by `v`.
fn replace_first_number(template: &str, v: &str) -> Option<String> {
    let b = template.as_bytes();
    let start = b.iter().position(|c| c.is_ascii_digit())?;
    let mut end = start;
    while end < b.len()
        && (b[end].is_ascii_digit()
            || (b[end] == b'.' && end + 1 < b.len() && b[end + 1].is_ascii_digit()))
    {
        end += 1;
    }
    let start = if start > 0 && b[start - 1] == b'-' {
        start - 1
    } else {
        start
    };
    Some(format!("{}{v}{}", &template[..start], &template[end..]))
}

fn number_cases(
    verb: &Verb,
    baselines: &[(usize, Parsed)],
    infinite_ok: &[&str],
    out: &mut Vec<Case>,
    notes: &mut Vec<String>,
    errors: &mut Vec<String>,
) {
    let key = verb.key();
    for a in &verb.args {
        let float = match a.value {
            Value::Float => true,
            Value::Int => false,
            Value::Compound { float } => float,
            _ => continue,
        };
        let compound = matches!(a.value, Value::Compound { .. });
        // A baseline that has it, else one where nothing present conflicts with it.
        let fits = |p: &Parsed| {
            !a.conflicts.iter().any(|c| p.at.contains_key(c))
                && !verb
                    .args
                    .iter()
                    .any(|o| p.at.contains_key(&o.id) && o.conflicts.contains(&a.id))
        };
        let chosen = baselines
            .iter()
            .find(|(_, p)| p.at.contains_key(&a.id))
            .or_else(|| baselines.iter().find(|(_, p)| fits(p)));
        let Some((b, p)) = chosen else {
            errors.push(format!("{key} {}: no baseline can take it", a.name()));
            continue;
        };
        let present = p.at.get(&a.id).and_then(|v| v.first().copied());
        let Some(long) = &a.long else {
            notes.push(format!("{key} {}: positional number not tested", a.name()));
            continue;
        };
        let template = present
            .map(|i| p.argv[i].clone())
            .or_else(|| a.default.clone());
        for (v, may_accept) in hostile(float) {
            let value = if compound {
                match template.as_deref().and_then(|t| replace_first_number(t, v)) {
                    Some(x) => x,
                    None => {
                        errors.push(format!(
                            "{key} {}: no valid value to start from (add it to a baseline)",
                            a.name()
                        ));
                        break;
                    }
                }
            } else {
                v.to_string()
            };
            let args = match present {
                Some(i) => {
                    let mut x = p.argv.clone();
                    // `--flag=value`, so that a leading '-' is the value.
                    x[i - 1] = format!("--{long}={value}");
                    x.remove(i);
                    x
                }
                None => {
                    let mut x = p.argv.clone();
                    x.push(format!("--{long}={value}"));
                    x
                }
            };
            let inf_ok = (v == "inf" || v == "1e300") && infinite_ok.contains(&a.id.as_str());
            let names = vec![format!("--{long}")];
            out.push(Case {
                kind: if !float && v == "1000000000" {
                    "10^9 for a size"
                } else {
                    "hostile number"
                },
                label: format!("{key}: --{long}={value}"),
                args,
                expect: if may_accept || inf_ok {
                    Expect::RefusedOrClean(names)
                } else {
                    Expect::Refused(names)
                },
                setup: Setup::None,
                baseline: *b,
                state: Vec::new(),
            });
        }
    }
}

/// The coverage errors of the table and baselines, and every case.
pub fn generate(
    subject: &Subject,
    cmd: &clap::Command,
    infinite_ok: &[&str],
) -> (Vec<Case>, Vec<String>, Vec<String>) {
    let mut cases = Vec::new();
    let mut errors = Vec::new();
    let mut notes = Vec::new();
    for verb in &subject.verbs {
        let key = verb.key();
        for a in &verb.args {
            if a.value == Value::Unclassified {
                errors.push(format!(
                    "{key} {}: a path with no role (type it InFile, OutFile, … from cli::paths)",
                    a.name()
                ));
            }
        }
        let mine: Vec<(usize, Parsed)> = subject
            .baselines
            .iter()
            .enumerate()
            .filter(|(_, (k, _))| *k == key)
            .filter_map(|(i, (_, args))| {
                let mut full: Vec<String> = verb.words.clone();
                full.extend(args.iter().cloned());
                match parse(cmd, verb, &full) {
                    Ok(p) => Some((i, p)),
                    Err(e) => {
                        errors.push(format!("baseline {key} {args:?} does not parse: {e}"));
                        None
                    }
                }
            })
            .collect();
        if mine.is_empty() {
            errors.push(format!(
                "{key}: no baseline (add a working invocation to the whole-CLI test's table)"
            ));
            continue;
        }
        for a in verb
            .args
            .iter()
            .filter(|a| matches!(a.value, Value::Path(r) if r.output()))
        {
            if !mine.iter().any(|(_, p)| p.at.contains_key(&a.id)) {
                errors.push(format!(
                    "{key} {}: an output no baseline writes (add it to a baseline)",
                    a.name()
                ));
            }
        }
        for (b, p) in &mine {
            path_cases(subject, verb, *b, p, &mut cases);
        }
        number_cases(
            verb,
            &mine,
            infinite_ok,
            &mut cases,
            &mut notes,
            &mut errors,
        );
    }
    (cases, errors, notes)
}

// ---- Checking a case ----

/// Whether this process may mount a tmpfs (root with the capability: a container's root may
/// lack it), tried once on a scratch folder.
pub fn can_mount() -> bool {
    if unsafe { libc::geteuid() } != 0 {
        return false;
    }
    let Ok(t) = tempfile::tempdir() else {
        return false;
    };
    let ok = Command::new("mount")
        .args(["-t", "tmpfs", "-o", "size=4096", "tmpfs"])
        .arg(t.path())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if ok {
        let _ = Command::new("umount").arg(t.path()).status();
    }
    ok
}

struct Mount(PathBuf);

impl Drop for Mount {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg("-l").arg(&self.0).status();
    }
}

fn prepare(dir: &Path, setup: &Setup) -> Option<Mount> {
    match setup {
        Setup::None => None,
        Setup::Symlink { link, to, real } => {
            if *real {
                std::fs::write(dir.join(to), "keep me").unwrap();
            }
            std::os::unix::fs::symlink(to, dir.join(link)).unwrap();
            None
        }
        Setup::Fifo(p) => {
            let st = Command::new("mkfifo").arg(dir.join(p)).status().unwrap();
            assert!(st.success());
            None
        }
        Setup::Folder(p) => {
            std::fs::create_dir_all(dir.join(p)).unwrap();
            std::fs::write(dir.join(p).join("keep.txt"), "keep me").unwrap();
            None
        }
        Setup::File(p) => {
            std::fs::write(dir.join(p), "keep me").unwrap();
            None
        }
        Setup::Tmpfs {
            dir: d,
            bytes,
            fill,
        } => {
            let m = dir.join(d);
            std::fs::create_dir_all(&m).unwrap();
            let st = Command::new("mount")
                .args(["-t", "tmpfs", "-o"])
                .arg(format!("size={}", (*bytes).max(4096)))
                .arg("tmpfs")
                .arg(&m)
                .status()
                .unwrap();
            assert!(st.success(), "mount tmpfs at {}", m.display());
            if *fill {
                use std::io::Write;
                let mut f = std::fs::File::create(m.join("filler")).unwrap();
                let block = vec![7u8; 4096];
                while f.write_all(&block).is_ok() {}
                let _ = f.sync_all();
            }
            Some(Mount(m))
        }
    }
}

/// Checks one case; `Err` says which promise broke.
fn check(subject: &Subject, case: &Case, ran: &Ran) -> Result<bool, String> {
    let t = workdir(subject);
    let dir = t.path();
    let mount = prepare(dir, &case.setup);
    let before = snapshot(dir);
    let o = run_in(subject, dir, &case.args);
    let after = snapshot(dir);
    let cmdline = format!("{:?}", case.args);
    if o.timed_out {
        return Err(format!(
            "ran past {} s without refusing (an up-front limit is missing): {cmdline}",
            subject.timeout.as_secs()
        ));
    }
    let lines: Vec<&str> = o.stderr.lines().filter(|l| !l.trim().is_empty()).collect();
    for bad in [
        "panicked",
        "internal error",
        "RUST_BACKTRACE",
        ".herdfit-",
        "memory allocation",
    ] {
        if o.stderr.contains(bad) {
            return Err(format!(
                "stderr has '{bad}': {} — {cmdline}",
                o.stderr.trim()
            ));
        }
    }
    let (names, may_accept) = match &case.expect {
        Expect::Refused(n) => (n, false),
        Expect::RefusedOrClean(n) => (n, true),
    };
    let hidden: Vec<&PathBuf> = after
        .keys()
        .filter(|p| {
            p.components()
                .any(|c| c.as_os_str().to_string_lossy().starts_with(".herdfit-"))
        })
        .collect();
    if !hidden.is_empty() {
        return Err(format!(
            "hidden temporary files left: {hidden:?} — {cmdline}"
        ));
    }
    if o.code == Some(0) {
        if !may_accept {
            return Err(format!("accepted (exit 0), should refuse: {cmdline}"));
        }
        // A clean run: the inputs unchanged, finite outputs.
        for (p, h) in &before {
            if after.get(p) != Some(h) && !ran.outputs.contains_key(p) {
                return Err(format!(
                    "{} changed by an accepted run: {cmdline}",
                    p.display()
                ));
            }
        }
        for p in after.keys().filter(|p| !before.contains_key(*p)) {
            let full = dir.join(p);
            let (bad, nulls) = text_problems(&full);
            if !bad.is_empty() {
                return Err(format!(
                    "{} holds {:?}: {cmdline}",
                    p.display(),
                    &bad[..bad.len().min(3)]
                ));
            }
            let base = ran.outputs.get(p).copied().unwrap_or(0);
            if nulls > base {
                return Err(format!(
                    "{} holds {nulls} nulls (the baseline {base}): {cmdline}",
                    p.display()
                ));
            }
            if p.extension().is_some_and(|e| e == "glb") {
                let g = glb_problems(&full);
                if !g.is_empty() {
                    return Err(format!(
                        "{} holds non-finite floats {g:?}: {cmdline}",
                        p.display()
                    ));
                }
            }
        }
        drop(mount);
        return Ok(true);
    }
    if lines.len() != 1 || !lines[0].starts_with("error: ") {
        return Err(format!(
            "exit {:?} with {} stderr lines (one `error:` line expected): {} — {cmdline}",
            o.code,
            lines.len(),
            o.stderr.trim()
        ));
    }
    for n in names {
        if !lines[0].contains(n.as_str()) {
            return Err(format!(
                "the error does not name '{n}': {} — {cmdline}",
                lines[0]
            ));
        }
    }
    // A state folder that holds a finished checkpoint is kept by design (a killed or failed fit
    // resumes from it); an empty one left behind is not.
    let kept = |p: &Path| {
        case.state.iter().any(|s| {
            let s = Path::new(s);
            p.starts_with(s)
                && after.keys().any(|q| {
                    q.starts_with(s)
                        && q != s
                        && dir.join(q).is_file()
                        && !q.to_string_lossy().contains(".herdfit-")
                })
        })
    };
    let changed_paths: Vec<&PathBuf> = before
        .keys()
        .chain(after.keys())
        .filter(|p| before.get(*p) != after.get(*p) && !kept(p))
        .collect();
    if !changed_paths.is_empty() {
        let changed: Vec<String> = changed_paths
            .into_iter()
            .map(|p| p.display().to_string())
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        return Err(format!(
            "refused ({}) but the folder changed: {changed:?} — {cmdline}",
            lines[0]
        ));
    }
    drop(mount);
    Ok(false)
}

/// Runs the suite: baselines first (each must succeed), then every case on `threads` threads.
pub fn run(subject: &Subject, cmd: &clap::Command, infinite_ok: &[&str], threads: usize) -> Report {
    let t0 = Instant::now();
    let mut report = Report::default();
    let (mut cases, errors, notes) = generate(subject, cmd, infinite_ok);
    report.failures.extend(errors);
    report.notes.extend(notes);
    if !can_mount() {
        report.notes.push(
            "cannot mount a tmpfs (not root, or no CAP_SYS_ADMIN): the full-disk cases are \
             skipped"
                .into(),
        );
        cases.retain(|c| !matches!(c.setup, Setup::Tmpfs { .. }));
    }
    // Baselines, in parallel.
    let n = subject.baselines.len();
    let rans: Mutex<Vec<Option<Ran>>> = Mutex::new(vec![None; n]);
    let next = Mutex::new(0usize);
    let fails = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let i = {
                    let mut g = next.lock().unwrap();
                    let i = *g;
                    *g += 1;
                    i
                };
                if i >= n {
                    break;
                }
                let (key, args) = &subject.baselines[i];
                if subject.long_verbs.iter().any(|(k, _)| k == key) {
                    rans.lock().unwrap()[i] = Some(Ran {
                        ok: true,
                        ..Ran::default()
                    });
                    continue;
                }
                let mut full: Vec<String> = key.split(' ').map(str::to_string).collect();
                full.extend(args.iter().cloned());
                let (ran, err) = run_baseline(subject, &full);
                if !ran.ok {
                    fails.lock().unwrap().push(format!(
                        "baseline `{} {}` failed: {}",
                        key,
                        args.join(" "),
                        err.trim()
                    ));
                }
                rans.lock().unwrap()[i] = Some(ran);
            });
        }
    });
    report.failures.extend(fails.into_inner().unwrap());
    let rans: Vec<Ran> = rans
        .into_inner()
        .unwrap()
        .into_iter()
        .map(Option::unwrap)
        .collect();
    if let Some((i, r)) = rans
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.seconds.total_cmp(&b.1.seconds))
    {
        report.notes.push(format!(
            "{} baselines in {:.0} s of runs, the slowest `{}` ({:.1} s)",
            n,
            rans.iter().map(|r| r.seconds).sum::<f64>(),
            subject.baselines[i].0,
            r.seconds
        ));
    }
    // Cases of failed baselines cannot be judged.
    cases.retain(|c| rans[c.baseline].ok);
    cases.retain(|c| {
        !matches!(
            c.setup,
            Setup::Tmpfs {
                bytes: 0,
                fill: false,
                ..
            }
        ) || rans[c.baseline].bytes >= 16 * 1024
    });
    for c in cases.iter_mut() {
        if let Setup::Tmpfs {
            bytes, fill: false, ..
        } = &mut c.setup
        {
            if *bytes == 0 {
                let total = rans[c.baseline].bytes;
                *bytes = (total / 2 / 4096 * 4096).max(4096);
            }
        }
    }
    // Each case's state folders, by the roles of its verb's flags.
    for c in cases.iter_mut() {
        let key = &subject.baselines[c.baseline].0;
        let Some(verb) = subject.verbs.iter().find(|v| v.key() == *key) else {
            continue;
        };
        for (i, t) in c.args.iter().enumerate() {
            let Some(long) = t.strip_prefix("--") else {
                continue;
            };
            let (name, inline) = match long.split_once('=') {
                Some((n, v)) => (n, Some(v.to_string())),
                None => (long, None),
            };
            let is_state = verb
                .args
                .iter()
                .any(|a| a.long.as_deref() == Some(name) && a.value == Value::Path(Role::StateDir));
            if is_state {
                if let Some(v) = inline.or_else(|| c.args.get(i + 1).cloned()) {
                    c.state.push(v);
                }
            }
        }
    }
    report.cases = cases.len();
    for c in &cases {
        *report.by_kind.entry(c.kind).or_default() += 1;
    }
    let next = Mutex::new(0usize);
    let results: Mutex<Vec<(usize, Result<bool, String>)>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| loop {
                let i = {
                    let mut g = next.lock().unwrap();
                    let i = *g;
                    *g += 1;
                    i
                };
                if i >= cases.len() {
                    break;
                }
                let c = &cases[i];
                let r = check(subject, c, &rans[c.baseline]);
                results.lock().unwrap().push((i, r));
            });
        }
    });
    let mut results = results.into_inner().unwrap();
    results.sort_by_key(|(i, _)| *i);
    for (i, r) in results {
        match r {
            Ok(true) => report.accepted += 1,
            Ok(false) => {}
            Err(e) => report
                .failures
                .push(format!("[{}] {}: {e}", cases[i].kind, cases[i].label)),
        }
    }
    report.seconds = t0.elapsed().as_secs_f64();
    report
}
