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
