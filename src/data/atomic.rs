//! Atomic writes shared by every command: a file or a folder appears whole or not at all, through
//! a temporary sibling renamed into place, under one output-path policy ([`check_target`]: no
//! devices, FIFOs or symlinks replaced, no input overwritten) and with temporary siblings removed on
//! SIGINT/SIGTERM and after a SIGKILL by the next run ([`cleanup`]). Under the command line every
//! writer here goes through the run's output [`plan`]: only declared outputs are written, and they
//! are renamed into place together when the run succeeds.

pub mod cleanup;
pub mod plan;
mod policy;
pub mod stdout;

pub use policy::{check_target, guard_inputs, note_input, read_input_text};
pub use stdout::{is_stdout, take_stdout};

use crate::error::{Error, Result};
use std::io::Write;
use std::path::Path;

/// On SIGINT or SIGTERM: the run's output plan is discarded, then every temporary sibling removed
/// ([`cleanup::install_signal_cleanup`]). Call first thing in `main`.
pub fn install_signal_cleanup() {
    cleanup::install_signal_cleanup(plan::abort_on_signal);
}

fn parent_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// The policy check and the removal of stale siblings, before any temporary sibling of `path`
/// is made.
fn prepare(path: &Path) -> Result<&Path> {
    check_target(path)?;
    let dir = parent_of(path);
    cleanup::remove_stale(dir, path);
    Ok(dir)
}

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so a reader
/// never sees a half-written file and a failed write leaves nothing behind.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    if is_stdout(path) {
        return stdout::write_all(path, bytes);
    }
    if path.is_dir() {
        return Err(Error::file(path, "cannot write: is a directory"));
    }
    let mode = plan::admit(path)?;
    let dir = prepare(path)?;
    let fail = |e: std::io::Error| Error::file(path, format!("cannot write: {e}"));
    let mut tmp = temp_builder(&cleanup::temp_prefix(path))
        .tempfile_in(dir)
        .map_err(fail)?;
    let name = tmp.path().to_path_buf();
    cleanup::register(&name, path);
    // Through the plain file: NamedTempFile's own writes add "at path <hidden temp>" to their
    // errors, and the user's error must name the output (issue #14).
    let written = tmp
        .as_file_mut()
        .write_all(bytes)
        .and_then(|_| tmp.as_file().sync_all());
    if let Err(e) = written {
        cleanup::unregister(&name);
        return Err(fail(e));
    }
    finish_file(tmp, path, mode)
}

/// Renames a finished temporary sibling into place, or hands it to the plan.
fn finish_file(tmp: tempfile::NamedTempFile, path: &Path, mode: plan::Admit) -> Result<()> {
    let name = tmp.path().to_path_buf();
    let fail = |e: std::io::Error| Error::file(path, format!("cannot write: {e}"));
    let done = match mode {
        plan::Admit::Staged => tmp
            .keep()
            .map(|(_, p)| plan::stage(p, path, false))
            .map_err(|e| fail(e.error)),
        plan::Admit::Now => check_target(path)
            .and_then(|_| tmp.persist(path).map(|_| ()).map_err(|e| fail(e.error))),
    };
    // A staged sibling stays registered (a signal removes it) until the plan renames it.
    if mode == plan::Admit::Now || done.is_err() {
        cleanup::unregister(&name);
    }
    done
}

/// Temporary siblings of output files: hidden names that say whose they are
/// ([`cleanup::temp_prefix`]), and the permissions of an ordinary file (rw-r--r--) rather than the
/// private 0600 of a temporary file, since they are renamed into place.
fn temp_builder(prefix: &str) -> tempfile::Builder<'_, 'static> {
    let mut b = tempfile::Builder::new();
    b.prefix(prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o644));
    }
    b
}

/// A temporary sibling of `path` (same folder, ordinary permissions) for writers that need a file
/// name of their own (PNG, AVI); [`persist`] renames it into place.
pub fn temp_sibling(path: &Path, suffix: &str) -> Result<tempfile::NamedTempFile> {
    if is_stdout(path) {
        return Err(stdout::not_a_stream(path, &format!("a {suffix} file")));
    }
    plan::admit(path)?;
    let dir = prepare(path)?;
    let t = temp_builder(&cleanup::temp_prefix(path))
        .suffix(suffix)
        .tempfile_in(dir)
        .map_err(|e| Error::file(path, format!("cannot write: {e}")))?;
    cleanup::register(t.path(), path);
    Ok(t)
}

/// Renames a finished [`temp_sibling`] into place (under a plan: stages it).
pub fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> Result<()> {
    let mode = match plan::admit(path) {
        Ok(m) => m,
        Err(e) => {
            cleanup::unregister(tmp.path());
            return Err(e);
        }
    };
    finish_file(tmp, path, mode)
}

/// Creates the folder `path` (and its missing parents) for a writer that fills it file by file: a
/// folder inside a folder being written whole, a state folder, or a declared folder of files.
/// Under a plan any other folder is an internal error, like an undeclared file.
pub fn make_dir(path: &Path) -> Result<()> {
    plan::admit_folder(path)?;
    std::fs::create_dir_all(path)
        .map_err(|e| Error::file(path, format!("cannot create folder: {e}")))
}

/// Checks early that `path` can be created (its folder exists and is writable, and the output-path
/// policy allows it), so long runs fail before they start rather than at the end. Under a plan this
/// declares `path` as an output ([`plan::declare`]): a verb's derived outputs (a default log name
/// beside `--out`) are declared this way before the run writes anything.
pub fn check_writable(path: &Path) -> Result<()> {
    plan::declare(path)
}

/// [`check_writable`] without a plan.
fn check_writable_now(path: &Path) -> Result<()> {
    if is_stdout(path) {
        return Ok(());
    }
    if path.is_dir() {
        return Err(Error::file(path, "cannot write: is a directory"));
    }
    let dir = prepare(path)?;
    temp_builder(&cleanup::temp_prefix(path))
        .tempfile_in(dir)
        .map(|_| ())
        .map_err(|e| Error::file(path, format!("cannot write: {e}")))
}

/// A file written through a temporary sibling and renamed into place by [`AtomicFile::commit`];
/// dropped without commit, it leaves nothing behind.
pub struct AtomicFile {
    path: std::path::PathBuf,
    out: std::io::BufWriter<Sink>,
}

/// Where an [`AtomicFile`] goes: its temporary sibling, or standard output for `-`.
enum Sink {
    Temp(tempfile::NamedTempFile),
    Stdout(stdout::Stdout),
}

impl Write for Sink {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        match self {
            Sink::Temp(t) => t.as_file_mut().write(b),
            Sink::Stdout(s) => s.write(b),
        }
    }
    fn flush(&mut self) -> std::io::Result<()> {
        match self {
            Sink::Temp(t) => t.as_file_mut().flush(),
            Sink::Stdout(s) => s.flush(),
        }
    }
}

impl AtomicFile {
    /// Starts writing `path`.
    pub fn create(path: &Path) -> Result<Self> {
        if is_stdout(path) {
            return Ok(AtomicFile {
                path: path.to_path_buf(),
                out: std::io::BufWriter::with_capacity(1 << 16, Sink::Stdout(stdout::Stdout)),
            });
        }
        if path.is_dir() {
            return Err(Error::file(path, "cannot write: is a directory"));
        }
        plan::admit(path)?;
        let dir = prepare(path)?;
        let tmp = temp_builder(&cleanup::temp_prefix(path))
            .tempfile_in(dir)
            .map_err(|e| Error::file(path, format!("cannot write: {e}")))?;
        cleanup::register(tmp.path(), path);
        Ok(AtomicFile {
            path: path.to_path_buf(),
            out: std::io::BufWriter::with_capacity(1 << 20, Sink::Temp(tmp)),
        })
    }

    /// Appends text.
    pub fn write_str(&mut self, s: &str) -> Result<()> {
        self.out
            .write_all(s.as_bytes())
            .map_err(|e| Error::file(&self.path, format!("cannot write: {e}")))
    }

    /// Flushes and renames the file into place.
    pub fn commit(self) -> Result<()> {
        let path = self.path;
        let fail = |e: std::io::Error| Error::file(&path, format!("cannot write: {e}"));
        let tmp = match self.out.into_inner().map_err(|e| fail(e.into_error()))? {
            Sink::Temp(t) => t,
            Sink::Stdout(mut s) => return s.flush().map_err(fail),
        };
        if let Err(e) = tmp.as_file().sync_all() {
            cleanup::unregister(tmp.path());
            return Err(fail(e));
        }
        persist(tmp, &path)
    }
}

/// A folder written all-or-nothing: files go into a hidden temporary sibling, and
/// [`AtomicDir::commit`] renames it into place. An existing target is replaced only if it is empty
/// or holds a previous herdfit output (`clip.json`, `report.json`, `params.json` or
/// `ablation.json`); anything else
/// is refused, so a mistyped `--out` never deletes a user's folder.
pub struct AtomicDir {
    target: std::path::PathBuf,
    tmp: tempfile::TempDir,
}

const OUTPUT_MARKERS: [&str; 4] = ["clip.json", "report.json", "params.json", "ablation.json"];

fn replaceable(dir: &Path) -> Result<bool> {
    check_target(dir)?;
    if !dir.exists() {
        return Ok(false);
    }
    if !dir.is_dir() {
        return Err(Error::file(dir, "cannot write: exists and is not a folder"));
    }
    let empty = std::fs::read_dir(dir)
        .map_err(|e| Error::file(dir, format!("cannot read: {e}")))?
        .next()
        .is_none();
    if empty || OUTPUT_MARKERS.iter().any(|m| dir.join(m).is_file()) {
        Ok(true)
    } else {
        Err(Error::file(
            dir,
            "exists and is not a herdfit output folder; refusing to replace it",
        ))
    }
}

impl AtomicDir {
    /// Starts writing the folder `target` (its parent must exist).
    pub fn create(target: &Path) -> Result<Self> {
        if is_stdout(target) {
            return Err(stdout::not_a_stream(target, "a folder"));
        }
        plan::admit(target)?;
        replaceable(target)?;
        let parent = parent_of(target);
        cleanup::remove_stale(parent, target);
        let tmp = tempfile::Builder::new()
            .prefix(&cleanup::temp_prefix(target))
            .tempdir_in(parent)
            .map_err(|e| Error::file(target, format!("cannot write: {e}")))?;
        cleanup::register(tmp.path(), target);
        plan::private(tmp.path());
        Ok(AtomicDir {
            target: target.to_path_buf(),
            tmp,
        })
    }

    /// The (temporary) folder itself, for writers that make their own files and folders in it.
    pub fn root(&self) -> &Path {
        self.tmp.path()
    }

    /// Path of a file inside the (temporary) folder.
    pub fn path(&self, name: &str) -> std::path::PathBuf {
        self.tmp.path().join(name)
    }

    /// Writes one file into the folder.
    pub fn write(&self, name: &str, bytes: &[u8]) -> Result<()> {
        std::fs::write(self.path(name), bytes)
            .map_err(|e| Error::file(self.target.join(name), format!("cannot write: {e}")))
    }

    /// Rewrites the text files of the folder (`.json`, `.md`, `.csv`, `.txt`, at any depth) that
    /// name the temporary folder so that they name the target instead: for writers that record
    /// the paths of what they wrote and read back inside the folder (the demo), so the committed
    /// files point at files that exist and do not depend on the temporary name.
    pub fn name_the_target_in_text_files(&self) -> Result<()> {
        let (from, to) = (
            self.tmp.path().display().to_string(),
            self.target.display().to_string(),
        );
        let mut stack = vec![self.tmp.path().to_path_buf()];
        let fail = |p: &Path, e: std::io::Error| {
            let shown = cleanup::user_facing(&p.display().to_string());
            Error::file(Path::new(&shown), format!("cannot rewrite: {e}"))
        };
        while let Some(dir) = stack.pop() {
            let mut entries: Vec<_> = std::fs::read_dir(&dir)
                .map_err(|e| fail(&dir, e))?
                .map(|e| e.map(|e| e.path()))
                .collect::<std::io::Result<_>>()
                .map_err(|e| fail(&dir, e))?;
            entries.sort();
            for p in entries {
                if p.is_dir() {
                    stack.push(p);
                    continue;
                }
                let text_file = p
                    .extension()
                    .and_then(|e| e.to_str())
                    .is_some_and(|e| matches!(e, "json" | "md" | "csv" | "txt"));
                if !text_file {
                    continue;
                }
                let Ok(text) = std::fs::read_to_string(&p) else {
                    continue;
                };
                if text.contains(&from) {
                    std::fs::write(&p, text.replace(&from, &to)).map_err(|e| fail(&p, e))?;
                }
            }
        }
        Ok(())
    }

    /// Renames the finished folder into place (replacing a previous output); under a plan, stages
    /// it.
    pub fn commit(self) -> Result<()> {
        let target = self.target;
        let fail = |e: std::io::Error| Error::file(&target, format!("cannot write: {e}"));
        if plan::admit(&target)? == plan::Admit::Staged {
            plan::stage(self.tmp.keep(), &target, true);
            return Ok(());
        }
        let replace = replaceable(&target)?;
        let tmp = self.tmp.keep();
        let done = commit_dir(&tmp, &target, replace).map_err(fail);
        cleanup::unregister(&tmp);
        done
    }
}

fn commit_dir(tmp: &Path, target: &Path, replace: bool) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        if let Err(e) = std::fs::set_permissions(tmp, std::fs::Permissions::from_mode(0o755)) {
            let _ = std::fs::remove_dir_all(tmp);
            return Err(e);
        }
    }
    if replace {
        let old = tmp.with_extension("old");
        if let Err(e) = std::fs::rename(target, &old) {
            let _ = std::fs::remove_dir_all(tmp);
            return Err(e);
        }
        if let Err(e) = std::fs::rename(tmp, target) {
            let _ = std::fs::rename(&old, target);
            let _ = std::fs::remove_dir_all(tmp);
            return Err(e);
        }
        let _ = std::fs::remove_dir_all(&old);
    } else if let Err(e) = std::fs::rename(tmp, target) {
        let _ = std::fs::remove_dir_all(tmp);
        return Err(e);
    }
    Ok(())
}

#[cfg(test)]
mod tests;
