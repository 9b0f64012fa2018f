//! Atomic writes shared by every command: a file or a folder appears whole or not at all.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::Path;

/// Writes `bytes` to `path` through a temporary file in the same folder and a rename, so a reader
/// never sees a half-written file and a failed write leaves nothing behind.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let fail = |e: std::io::Error| Error::file(path, format!("cannot write: {e}"));
    let mut tmp = temp_builder().tempfile_in(dir).map_err(fail)?;
    tmp.write_all(bytes).map_err(fail)?;
    tmp.as_file().sync_all().map_err(fail)?;
    tmp.persist(path).map_err(|e| fail(e.error))?;
    Ok(())
}

/// Temporary siblings of output files: hidden names, and the permissions of an ordinary file
/// (rw-r--r--) rather than the private 0600 of a temporary file, since they are renamed into place.
fn temp_builder() -> tempfile::Builder<'static, 'static> {
    let mut b = tempfile::Builder::new();
    b.prefix(".herdfit-").suffix(".tmp");
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
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    temp_builder()
        .suffix(suffix)
        .tempfile_in(dir)
        .map_err(|e| Error::file(path, format!("cannot write: {e}")))
}

/// Renames a finished [`temp_sibling`] into place.
pub fn persist(tmp: tempfile::NamedTempFile, path: &Path) -> Result<()> {
    tmp.persist(path)
        .map(|_| ())
        .map_err(|e| Error::file(path, format!("cannot write: {}", e.error)))
}

/// Checks early that `path` can be created (its folder exists and is writable), so long runs fail
/// before they start rather than at the end.
pub fn check_writable(path: &Path) -> Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    if path.is_dir() {
        return Err(Error::file(path, "cannot write: is a directory"));
    }
    tempfile::Builder::new()
        .prefix(".herdfit-probe-")
        .tempfile_in(dir)
        .map(|_| ())
        .map_err(|e| Error::file(path, format!("cannot write: {e}")))
}

/// A file written through a temporary sibling and renamed into place by [`AtomicFile::commit`];
/// dropped without commit, it leaves nothing behind.
pub struct AtomicFile {
    path: std::path::PathBuf,
    out: std::io::BufWriter<tempfile::NamedTempFile>,
}

impl AtomicFile {
    /// Starts writing `path`.
    pub fn create(path: &Path) -> Result<Self> {
        let dir = match path.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        if path.is_dir() {
            return Err(Error::file(path, "cannot write: is a directory"));
        }
        let tmp = temp_builder()
            .tempfile_in(dir)
            .map_err(|e| Error::file(path, format!("cannot write: {e}")))?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            out: std::io::BufWriter::with_capacity(1 << 20, tmp),
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
        let tmp = self.out.into_inner().map_err(|e| fail(e.into_error()))?;
        tmp.as_file().sync_all().map_err(fail)?;
        tmp.persist(&path).map_err(|e| fail(e.error))?;
        Ok(())
    }
}

/// A folder written all-or-nothing: files go into a hidden temporary sibling, and
/// [`AtomicDir::commit`] renames it into place. An existing target is replaced only if it is empty
/// or holds a previous herdfit output (`clip.json`, `report.json` or `params.json`); anything else
/// is refused, so a mistyped `--out` never deletes a user's folder.
pub struct AtomicDir {
    target: std::path::PathBuf,
    tmp: tempfile::TempDir,
}

const OUTPUT_MARKERS: [&str; 3] = ["clip.json", "report.json", "params.json"];

fn replaceable(dir: &Path) -> Result<bool> {
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
        replaceable(target)?;
        let parent = match target.parent() {
            Some(d) if !d.as_os_str().is_empty() => d,
            _ => Path::new("."),
        };
        let tmp = tempfile::Builder::new()
            .prefix(".herdfit-")
            .tempdir_in(parent)
            .map_err(|e| Error::file(target, format!("cannot write: {e}")))?;
        Ok(AtomicDir {
            target: target.to_path_buf(),
            tmp,
        })
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

    /// Renames the finished folder into place (replacing a previous output).
    pub fn commit(self) -> Result<()> {
        let target = self.target;
        let fail = |e: std::io::Error| Error::file(&target, format!("cannot write: {e}"));
        let replace = replaceable(&target)?;
        let tmp = self.tmp.keep();
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(&tmp, std::fs::Permissions::from_mode(0o755)).map_err(fail)?;
        }
        if replace {
            let old = tmp.with_extension("old");
            std::fs::rename(&target, &old).map_err(fail)?;
            if let Err(e) = std::fs::rename(&tmp, &target) {
                let _ = std::fs::rename(&old, &target);
                let _ = std::fs::remove_dir_all(&tmp);
                return Err(fail(e));
            }
            let _ = std::fs::remove_dir_all(&old);
        } else if let Err(e) = std::fs::rename(&tmp, &target) {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(fail(e));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_dir_replaces_outputs_only() {
        let dir = tempfile::tempdir().unwrap();
        let t = dir.path().join("clip");
        let d = AtomicDir::create(&t).unwrap();
        d.write("clip.json", b"{}").unwrap();
        assert!(!t.exists(), "nothing visible before commit");
        d.commit().unwrap();
        assert!(t.join("clip.json").is_file());
        // A previous output is replaced whole.
        let d = AtomicDir::create(&t).unwrap();
        d.write("clip.json", b"{\"v\": 2}").unwrap();
        d.write("other.txt", b"x").unwrap();
        d.commit().unwrap();
        assert_eq!(
            std::fs::read_to_string(t.join("clip.json")).unwrap(),
            "{\"v\": 2}"
        );
        // A folder of someone else's files is refused.
        let home = dir.path().join("home");
        std::fs::create_dir(&home).unwrap();
        std::fs::write(home.join("thesis.tex"), "…").unwrap();
        let e = AtomicDir::create(&home).err().unwrap().to_string();
        assert!(e.contains("refusing"), "{e}");
        // A dropped, uncommitted folder leaves nothing.
        drop(AtomicDir::create(&dir.path().join("never")).unwrap());
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        assert_eq!(names.len(), 2, "{names:?}");
    }

    #[test]
    fn atomic_write_replaces_and_reports_unwritable() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read_to_string(&p).unwrap(), "two");
        let bad = dir.path().join("missing-dir").join("a.txt");
        let e = write_atomic(&bad, b"x").unwrap_err().to_string();
        assert!(
            e.contains("missing-dir") && e.contains("cannot write"),
            "{e}"
        );
        assert!(check_writable(&bad).is_err());
        // Nothing but the file itself is left in the folder.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
