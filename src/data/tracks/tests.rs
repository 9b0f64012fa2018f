//! Unit tests of the tracks format.

use super::*;

/// A temporary folder holding the file `name` with `text`, and the file's path.
fn file_with(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

fn row(frame: u64, id: u64, x: f64, y: f64) -> TrackRow {
    TrackRow {
        frame,
        time: frame as f64 / 25.0,
        id,
        pos: [x, y, 0.0],
        vel: None,
        role: None,
    }
}

#[test]
fn round_trip_2d_and_3d_with_sidecar() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.csv");
    let mut rows = vec![
        row(1, 2, 0.5, -1.0),
        row(0, 7, 1.0, 2.0),
        row(0, 2, 0.1, 0.2),
    ];
    for r in &mut rows {
        r.vel = Some([0.25, -0.5, 0.0]);
        r.role = Some("follower".into());
    }
    let t = Tracks::new(TracksMeta::new(Units::Metres, 25.0, 2), rows).unwrap();
    assert_eq!(t.rows[0].id, 2, "sorted by (frame, id)");
    t.save(&p).unwrap();
    let back = Tracks::load(&p).unwrap();
    assert_eq!(back, t);
    assert!(std::fs::read_to_string(&p)
        .unwrap()
        .starts_with("frame,time,id,x,y,vx,vy,role\n0,0,2,0.1,0.2,0.25,-0.5,follower\n"));
    let mut t3 = t.clone();
    t3.meta.dimension = 3;
    for r in &mut t3.rows {
        r.pos[2] = 3.5;
        r.vel = Some([1.0, 2.0, -3.0]);
    }
    let p3 = dir.path().join("t3.csv");
    t3.save(&p3).unwrap();
    assert_eq!(Tracks::load(&p3).unwrap(), t3);
    assert_eq!(t3.frames().len(), 2);
    assert_eq!(t3.by_id()[&2], vec![0, 2]);
    assert_eq!(t3.ids(), vec![2, 7]);
}

#[test]
fn traj_csv_without_sidecar_reads_with_defaults() {
    let (_dir, p) = file_with(
        "traj.csv",
        "frame,time,id,x,y,vx,vy,role\n0,0,0,1,2,1,0,leader\n0,0,1,3,2,1,0,follower\n\
         1,0.04,0,1.04,2,1,0,leader\n1,0.04,1,3.04,2,1,0,follower\n",
    );
    let t = Tracks::load(&p).unwrap();
    assert_eq!(t.meta.units, Units::BodyLengths);
    assert_eq!(t.meta.dimension, 2);
    assert!((t.meta.fps - 25.0).abs() < 1e-9);
    assert_eq!(t.rows.len(), 4);
    assert_eq!(t.rows[0].role.as_deref(), Some("leader"));
}

#[test]
fn bad_tracks_name_the_line_or_row() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("bad.csv");
    let cases = [
        (
            "frame,time,id,x,y\n1,0.04,0,1,2\n0,0,0,1,2\n",
            "line 3: frame 0 after frame 1",
        ),
        (
            "frame,time,id,x,y\n0,0,0,1,2\n0,0,0,1,3\n",
            "duplicate (frame, id)",
        ),
        (
            "frame,time,id,x,y\n0,0,0,NaN,2\n1,0.1,0,1,2\n",
            "line 2: x is NaN",
        ),
        ("frame,time,id,x\n0,0,0,1\n", "lacks column 'y'"),
        (
            "frame,time,id,x,y\n0,0,0,1,2\n1,0,0,1,2\n",
            "does not increase",
        ),
        ("frame,time,id,x,y\n0,0,-1,1,2\n", "id = '-1'"),
        ("", "empty file"),
        (
            "frame,time,id,x,y\n0,0,0,1,2\n",
            "frame rate cannot be read",
        ),
    ];
    for (text, want) in cases {
        std::fs::write(&p, text).unwrap();
        let e = Tracks::load(&p).unwrap_err().to_string();
        assert!(e.contains("bad.csv") && e.contains(want), "{want}: {e}");
    }
    // A sidecar that disagrees with the CSV.
    std::fs::write(&p, "frame,time,id,x,y\n0,0,0,1,2\n").unwrap();
    let with_sidecar = |json: &str| {
        std::fs::write(dir.path().join("bad.json"), json).unwrap();
        Tracks::load(&p).unwrap_err().to_string()
    };
    let e = with_sidecar(r#"{"schema":"herdfit.tracks/1","units":"m","fps":10,"dimension":3}"#);
    assert!(e.contains("bad.json") && e.contains("dimension = 3"), "{e}");
    let e =
        with_sidecar(r#"{"schema":"herdfit.tracks/1","units":"furlong","fps":10,"dimension":2}"#);
    assert!(e.contains("bad.json") && e.contains("furlong"), "{e}");
}

#[test]
fn eth_ucy_frames_become_consecutive_steps() {
    let (_dir, p) = file_with(
        "scene.txt",
        "780\t1.0\t8.46\t3.59\n790\t1.0\t9.0\t3.5\n790\t2.0\t1.5\t2.0\n800\t2.0\t1.9\t2.1\n",
    );
    let t = read_eth_ucy(&p, 2.5).unwrap();
    assert_eq!(t.meta.units, Units::Metres);
    let f: Vec<(u64, u64)> = t.rows.iter().map(|r| (r.frame, r.id)).collect();
    assert_eq!(f, vec![(0, 1), (1, 1), (1, 2), (2, 2)]);
    assert!((t.rows[3].time - 0.8).abs() < 1e-12);
    std::fs::write(&p, "780 1 2\n").unwrap();
    let e = read_eth_ucy(&p, 2.5).unwrap_err().to_string();
    assert!(e.contains("line 1: expected 4 fields"), "{e}");
    std::fs::write(&p, "780 1 2 3\n780 1 2 3\n").unwrap();
    let e = read_eth_ucy(&p, 2.5).unwrap_err().to_string();
    assert!(e.contains("duplicate (frame, id)"), "{e}");
}
