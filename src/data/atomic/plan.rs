//! The output plan (issue #47): one run's outputs as one transaction. The command line declares
//! every file and folder a run will write and every input it names ([`Plan`]) before the verb
//! runs; [`Plan::begin`] checks each output against every input and every input's sidecar, the
//! other outputs, devices, FIFOs and symbolic links, and that its folder is writable; from then on
//! every writer in [`super`] asks the plan ([`admit`]) before it makes a temporary sibling, writes
//! there, and hands the finished sibling to the plan ([`stage`]) instead of renaming it. [`finish`]
//! renames every staged output into place together at the end (each replaced output kept aside
//! until all renames succeed, and put back if one fails); [`abort`] — on an error, a panic or a
//! signal — removes them all. A refused or failed run therefore leaves nothing, whatever it had
//! written, and a writer asked for a file nobody declared fails loudly (an internal error) instead
//! of writing it.
//!
//! Library callers that open no plan (tests, notebooks' Rust users) get the writers' own atomic
//! behaviour: each file renamed into place when it is done.
//!
//! Kinds of output: a file ([`Kind::File`]), a folder written whole ([`Kind::Dir`], or
//! [`Kind::DirAll`] which may create missing parent folders — removed again if the run fails), and
//! a state folder ([`Kind::State`], a fit's checkpoints: written as the run goes so that a killed
//! run can resume, never staged). Files inside a folder being written (an [`super::AtomicDir`]'s
//! temporary folder, or a state folder) are free: the folder is the unit.

use super::cleanup;
use super::policy::{canonical_target, check_target, note_input};
use crate::error::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// What an output is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// One file, renamed into place at the end.
    File,
    /// A folder written whole (its parent must exist).
    Dir,
    /// A folder written whole; missing parent folders are created (and removed if the run fails).
    DirAll,
    /// A folder written as the run goes (checkpoints), kept if the run fails.
    State,
    /// A folder files are written into, each file staged on its own (created if missing, and
    /// then removed if the run fails; other files in it kept).
    Files,
}

/// One declared output: the path as given, what names it to the user (`--out`, `the sidecar of
/// --out`), its kind.
#[derive(Clone, Debug)]
struct Declared {
    path: PathBuf,
    canon: PathBuf,
    what: String,
    kind: Kind,
}

/// One input: the path as given, its canonical form, and for a tracks CSV the sidecar it reads.
#[derive(Clone, Debug)]
struct Input {
    path: PathBuf,
    canon: PathBuf,
    what: String,
}

/// Every file a run reads and writes, declared before it runs.
#[derive(Clone, Debug, Default)]
pub struct Plan {
    inputs: Vec<Input>,
    outputs: Vec<(PathBuf, String, Kind)>,
}

/// A written output waiting for the end of the run.
#[derive(Debug)]
struct Staged {
    tmp: PathBuf,
    target: PathBuf,
    dir: bool,
}

/// The plan of the running command.
#[derive(Debug, Default)]
struct Active {
    inputs: Vec<Input>,
    outputs: Vec<Declared>,
    staged: Vec<Staged>,
    /// Folders whose contents are written freely (temporary folders of folders being written).
    private: Vec<PathBuf>,
    /// Parent folders created for [`Kind::DirAll`] outputs, outermost first.
    made: Vec<PathBuf>,
    /// Set by the first temporary sibling of a declared output: declarations end there.
    writing: bool,
}

static ACTIVE: Mutex<Option<Active>> = Mutex::new(None);

mod commit;
pub use commit::{abort, abort_on_signal, finish};

fn lock() -> std::sync::MutexGuard<'static, Option<Active>> {
    ACTIVE.lock().unwrap_or_else(|e| e.into_inner())
}

/// Whether a plan is open (the command line runs one).
pub fn active() -> bool {
    lock().is_some()
}

/// The sidecar a tracks CSV is read with (`x.csv` → `x.json`); `None` for other files.
pub fn sidecar_of(path: &Path) -> Option<PathBuf> {
    let ext = path.extension()?.to_str()?;
    ext.eq_ignore_ascii_case("csv")
        .then(|| path.with_extension("json"))
}

fn canon(path: &Path) -> PathBuf {
    canonical_target(path).unwrap_or_else(|| path.to_path_buf())
}

impl Plan {
    /// An empty plan.
    pub fn new() -> Self {
        Self::default()
    }

    /// A file or folder the run reads (`what` names it: `TRACKS`, `--camera`). A tracks CSV's
    /// sidecar is protected with it, whether or not it exists: an output written there would
    /// change how the CSV reads.
    pub fn input(&mut self, path: &Path, what: &str) {
        if super::is_stdout(path) {
            return;
        }
        self.inputs.push(Input {
            path: path.to_path_buf(),
            canon: canon(path),
            what: what.to_string(),
        });
        if let Some(side) = sidecar_of(path) {
            self.inputs.push(Input {
                canon: canon(&side),
                path: side,
                what: format!("the sidecar of {what} {}", path.display()),
            });
        }
    }

    /// An output of `kind` (`what` names it: `--out`).
    pub fn output(&mut self, path: &Path, what: &str, kind: Kind) {
        self.outputs
            .push((path.to_path_buf(), what.to_string(), kind));
    }

    /// A tracks CSV output and its sidecar.
    pub fn tracks_output(&mut self, path: &Path, what: &str) {
        self.output(path, what, Kind::File);
        if let Some(side) = sidecar_of(path) {
            self.output(
                &side,
                &format!("the sidecar of {what} {}", path.display()),
                Kind::File,
            );
        }
    }

    /// Checks every output and opens the plan: from here on every write goes through it.
    pub fn begin(self) -> Result<()> {
        for i in &self.inputs {
            note_input(&i.path);
        }
        let mut a = Active {
            inputs: self.inputs,
            ..Active::default()
        };
        for (path, what, kind) in self.outputs {
            a.add(&path, &what, kind)?;
        }
        let made = make_parents(&a.outputs)?;
        a.made = made;
        *lock() = Some(a);
        Ok(())
    }
}

impl Active {
    /// Checks one output against the inputs, the outputs so far and the file system, and records it.
    fn add(&mut self, path: &Path, what: &str, kind: Kind) -> Result<()> {
        if super::is_stdout(path) {
            return Ok(());
        }
        let c = canon(path);
        for i in &self.inputs {
            if i.canon == c {
                let victim = if i.what.starts_with("the sidecar") {
                    format!("{}, an input of this command", i.what)
                } else {
                    "an input of this command".to_string()
                };
                return Err(Error::file(path, clash(what, &victim)));
            }
        }
        for o in &self.outputs {
            if o.canon == c {
                return Err(Error::file(
                    path,
                    format!(
                        "is written twice ({} and {}); give each output its own name",
                        o.what, what
                    ),
                ));
            }
            let dir = |k| matches!(k, Kind::Dir | Kind::DirAll | Kind::State | Kind::Files);
            if (dir(o.kind) && c.starts_with(&o.canon)) || (dir(kind) && o.canon.starts_with(&c)) {
                return Err(Error::file(
                    path,
                    format!(
                        "overlaps another output of this command ({} {}); give each output its \
                         own place",
                        o.what,
                        o.path.display()
                    ),
                ));
            }
        }
        // A folder where a file goes is named as such (issue #14's wording) before the policy's
        // finer reasons (a folder holding an input).
        if kind == Kind::File && path.is_dir() {
            return Err(Error::file(path, "cannot write: is a directory"));
        }
        check_target(path)?;
        writable(path, kind)?;
        cleanup::remove_stale(super::parent_of(path), path);
        self.outputs.push(Declared {
            path: path.to_path_buf(),
            canon: c,
            what: what.to_string(),
            kind,
        });
        Ok(())
    }

    /// Declares `path` when it lies in a declared [`Kind::Files`] folder (`true`), checked like any
    /// output.
    fn add_in_folder(&mut self, path: &Path) -> Result<bool> {
        let c = canon(path);
        let Some(folder) = self
            .outputs
            .iter()
            .find(|o| o.kind == Kind::Files && c.starts_with(&o.canon) && c != o.canon)
        else {
            return Ok(false);
        };
        let what = format!("a file in {} {}", folder.what, folder.path.display());
        // The folder itself is declared; its files are judged against the inputs and one another.
        let (inputs, outputs) = (&self.inputs, &self.outputs);
        let mut probe = Active {
            inputs: inputs.clone(),
            outputs: outputs
                .iter()
                .filter(|o| o.kind != Kind::Files)
                .cloned()
                .collect(),
            ..Active::default()
        };
        probe.add(path, &what, Kind::File)?;
        let d = probe.outputs.pop().expect("just added");
        self.outputs.push(d);
        Ok(true)
    }

    fn declared(&self, path: &Path) -> Option<&Declared> {
        let c = canon(path);
        self.outputs.iter().find(|o| o.canon == c)
    }

    /// Inside a private folder or a state folder: written freely.
    fn free(&self, path: &Path) -> bool {
        if self.private.iter().any(|p| path.starts_with(p)) {
            return true;
        }
        let c = canon(path);
        self.private.iter().any(|p| c.starts_with(canon(p)))
            || self
                .outputs
                .iter()
                .any(|o| o.kind == Kind::State && c.starts_with(&o.canon) && c != o.canon)
    }
}

/// Why an output may not go where a `victim` is: the user's own name for it needs no more words;
/// a derived output (a sidecar, a default report) says what it is.
fn clash(what: &str, victim: &str) -> String {
    if what.contains(' ') {
        format!("is {victim}; refusing to write {what} there")
    } else {
        format!("is {victim}; refusing to overwrite it")
    }
}

/// The folder that must exist and be writable for `path` of `kind`, and the check itself.
fn writable(path: &Path, kind: Kind) -> Result<()> {
    let fail = |e: std::io::Error| Error::file(path, format!("cannot write: {e}"));
    match kind {
        Kind::File => {
            if path.is_dir() {
                return Err(Error::file(path, "cannot write: is a directory"));
            }
        }
        Kind::Dir | Kind::DirAll => {
            super::replaceable(path)?;
        }
        Kind::State | Kind::Files => {
            if path.exists() && !path.is_dir() {
                return Err(Error::file(
                    path,
                    "cannot write: exists and is not a folder",
                ));
            }
            if kind == Kind::Files && path.is_dir() {
                return tempfile::Builder::new()
                    .prefix(&cleanup::temp_prefix(path))
                    .tempfile_in(path)
                    .map(|_| ())
                    .map_err(fail);
            }
        }
    }
    let mut dir = super::parent_of(path).to_path_buf();
    if kind == Kind::DirAll {
        while !dir.exists() {
            match dir.parent() {
                Some(p) if !p.as_os_str().is_empty() => dir = p.to_path_buf(),
                _ => dir = PathBuf::from("."),
            }
        }
    }
    if !dir.is_dir() {
        return Err(Error::file(
            path,
            format!("cannot write: the folder {} does not exist", dir.display()),
        ));
    }
    tempfile::Builder::new()
        .prefix(&cleanup::temp_prefix(path))
        .tempfile_in(&dir)
        .map(|_| ())
        .map_err(fail)
}

/// Creates the missing parents of [`Kind::DirAll`] outputs and the missing [`Kind::Files`] and
/// [`Kind::State`] folders themselves; returns them outermost first. A run that fails removes
/// those still empty (a state folder holding a finished checkpoint stays, to resume from).
fn make_parents(outputs: &[Declared]) -> Result<Vec<PathBuf>> {
    let mut made = Vec::new();
    for o in outputs
        .iter()
        .filter(|o| matches!(o.kind, Kind::DirAll | Kind::Files | Kind::State))
    {
        let mut missing = Vec::new();
        let mut d = match o.kind {
            Kind::Files | Kind::State => o.path.clone(),
            _ => super::parent_of(&o.path).to_path_buf(),
        };
        while !d.exists() {
            missing.push(d.clone());
            match d.parent() {
                Some(p) if !p.as_os_str().is_empty() => d = p.to_path_buf(),
                _ => break,
            }
        }
        for m in missing.into_iter().rev() {
            if let Err(e) = std::fs::create_dir(&m) {
                remove_made(&made);
                return Err(Error::file(&o.path, format!("cannot write: {e}")));
            }
            made.push(m);
        }
    }
    Ok(made)
}

fn remove_made(made: &[PathBuf]) {
    for m in made.iter().rev() {
        let _ = std::fs::remove_dir(m);
    }
}

/// How a writer may write `path`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Admit {
    /// No plan, or a file inside a folder being written: write and rename as the writer always did.
    Now,
    /// A declared output: write a temporary sibling and [`stage`] it.
    Staged,
}

/// Asks the plan whether `path` may be written; an undeclared path is an internal error (the verb
/// forgot to declare it), not a silent write.
pub fn admit(path: &Path) -> Result<Admit> {
    let mut g = lock();
    let Some(a) = g.as_mut() else {
        return Ok(Admit::Now);
    };
    if super::is_stdout(path) || a.free(path) {
        return Ok(Admit::Now);
    }
    if a.declared(path).is_none() {
        a.add_in_folder(path)?;
    }
    match a.declared(path).map(|o| o.kind) {
        Some(Kind::State) => Ok(Admit::Now),
        Some(_) => {
            a.writing = true;
            Ok(Admit::Staged)
        }
        None => Err(undeclared(path)),
    }
}

/// Asks the plan whether the folder `path` may be created: inside a folder being written, a state
/// folder, or a declared folder (of files, or the state folder itself).
pub fn admit_folder(path: &Path) -> Result<()> {
    let g = lock();
    let Some(a) = g.as_ref() else {
        return Ok(());
    };
    let c = canon(path);
    let declared = a
        .outputs
        .iter()
        .any(|o| matches!(o.kind, Kind::Files | Kind::State) && o.canon == c);
    if a.free(path) || declared {
        Ok(())
    } else {
        Err(undeclared(path))
    }
}

fn undeclared(path: &Path) -> Error {
    Error::Internal(format!(
        "{}: written but not declared in the run's output plan (data::atomic::plan)",
        path.display()
    ))
}

/// Declares an output the verb derives itself (a default report name beside `--out`) before it
/// writes anything; with no plan open, checks that `path` can be written.
pub fn declare(path: &Path) -> Result<()> {
    let mut g = lock();
    let Some(a) = g.as_mut() else {
        drop(g);
        return super::check_writable_now(path);
    };
    if super::is_stdout(path) || a.free(path) || a.declared(path).is_some() {
        return Ok(());
    }
    if a.add_in_folder(path)? {
        return Ok(());
    }
    if a.writing {
        return Err(Error::Internal(format!(
            "{}: declared after the run began writing (data::atomic::plan)",
            path.display()
        )));
    }
    a.add(path, &format!("the output {}", path.display()), Kind::File)
}

/// Records the temporary folder of a folder being written: files inside it are free.
pub fn private(tmp: &Path) {
    if let Some(a) = lock().as_mut() {
        a.private.push(tmp.to_path_buf());
    }
}

/// Hands a finished temporary sibling `tmp` of the declared `target` to the plan; an earlier one
/// for the same target is removed.
pub fn stage(tmp: PathBuf, target: &Path, dir: bool) {
    let mut g = lock();
    let Some(a) = g.as_mut() else {
        return;
    };
    if let Some(i) = a.staged.iter().position(|s| s.target == target) {
        let old = a.staged.remove(i);
        remove(&old.tmp, old.dir);
        cleanup::unregister(&old.tmp);
    }
    a.staged.push(Staged {
        tmp,
        target: target.to_path_buf(),
        dir,
    });
}

/// Where a staged output can be read back during the run (its temporary sibling), or `path`.
pub fn current(path: &Path) -> PathBuf {
    let g = lock();
    g.as_ref()
        .and_then(|a| {
            let c = canon(path);
            a.staged
                .iter()
                .find(|s| s.target == path || canon(&s.target) == c)
        })
        .map_or_else(|| path.to_path_buf(), |s| s.tmp.clone())
}

fn remove(p: &Path, dir: bool) {
    if dir {
        let _ = std::fs::remove_dir_all(p);
    } else {
        let _ = std::fs::remove_file(p);
    }
}
