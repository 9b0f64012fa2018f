//! The jackdaw flights of Ling et al. (`../shared/data/jackdaws/*.csv`): real 3D flock tracks from a
//! multi-camera rig, CSV `frame,id,t,x,y,z,vx,vy,vz` (60 frames per second, t in seconds from the
//! first frame, metres and m/s, z up). Read into `herdfit.tracks/1` (3D, metres).

use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use std::path::Path;

/// The header line of the jackdaw files.
pub const JACKDAW_HEADER: &str = "frame,id,t,x,y,z,vx,vy,vz";

/// Whether `path` starts with the jackdaw header (so [`load_tracks`] reads it as such).
pub fn is_jackdaw_csv(path: &Path) -> bool {
    use std::io::BufRead;
    let Ok(f) = std::fs::File::open(path) else {
        return false;
    };
    let mut line = String::new();
    std::io::BufReader::new(f).read_line(&mut line).is_ok() && line.trim() == JACKDAW_HEADER
}

/// Reads a jackdaw flight as 3D tracks in metres; the frame rate is read off the `t` column.
pub fn read_jackdaw(path: &Path) -> Result<Tracks> {
    crate::data::atomic::note_input(path);
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == JACKDAW_HEADER => {}
        _ => {
            return Err(Error::file(
                path,
                format!("expected the header {JACKDAW_HEADER}"),
            ))
        }
    }
    let mut rows = Vec::new();
    for (ln, line) in lines {
        if line.trim().is_empty() {
            continue;
        }
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        if f.len() != 9 {
            return Err(Error::file(
                path,
                format!("line {}: expected 9 fields, found {}", ln + 1, f.len()),
            ));
        }
        let v = crate::data::csv::frame_id_row(
            path,
            ln,
            &f,
            ["frame", "id", "t", "x", "y", "z", "vx", "vy", "vz"],
        )?;
        rows.push(TrackRow {
            frame: v[0] as u64,
            time: v[2],
            id: v[1] as u64,
            pos: [v[3], v[4], v[5]],
            vel: Some([v[6], v[7], v[8]]),
            role: None,
        });
    }
    let (first, last) = match (
        rows.iter().min_by_key(|r| r.frame),
        rows.iter().max_by_key(|r| r.frame),
    ) {
        (Some(a), Some(b)) if b.frame > a.frame && b.time > a.time => (a.clone(), b.clone()),
        _ => {
            return Err(Error::file(
                path,
                "fewer than two frames: the frame rate cannot be read off the t column",
            ))
        }
    };
    let fps = (last.frame - first.frame) as f64 / (last.time - first.time);
    let mut meta = TracksMeta::new(Units::Metres, fps, 3);
    meta.provenance = serde_json::json!({
        "format": "jackdaw (Ling et al.)",
        "source": path.display().to_string(),
    });
    Tracks::new(meta, rows).map_err(|e| e.in_file(path))
}

/// Reads any tracks file herdfit knows: a jackdaw flight (by its header) or `herdfit.tracks/1`.
pub fn load_tracks(path: &Path) -> Result<Tracks> {
    if is_jackdaw_csv(path) {
        read_jackdaw(path)
    } else {
        Tracks::load(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_jackdaw_layout_and_rejects_bad_rows() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("j.csv");
        std::fs::write(
            &p,
            "frame,id,t,x,y,z,vx,vy,vz\n0,3,0.00000,1,2,3,4,5,6\n0,1,0.00000,0,0,0,0,0,0\n\
             2,1,0.03333,0.1,0,0,3,0,0\n",
        )
        .unwrap();
        assert!(is_jackdaw_csv(&p));
        let t = load_tracks(&p).unwrap();
        assert_eq!(t.meta.dimension, 3);
        assert_eq!(t.meta.units, Units::Metres);
        assert!((t.meta.fps - 60.006).abs() < 0.01, "{}", t.meta.fps);
        assert_eq!(t.rows[0].id, 1);
        assert_eq!(t.rows[1].pos, [1.0, 2.0, 3.0]);
        assert_eq!(t.rows[1].vel, Some([4.0, 5.0, 6.0]));
        std::fs::write(
            &p,
            "frame,id,t,x,y,z,vx,vy,vz\n0,1,0,1,2,nan,0,0,0\n1,1,0.1,0,0,0,0,0,0\n",
        )
        .unwrap();
        let e = read_jackdaw(&p).unwrap_err().to_string();
        assert!(e.contains("j.csv") && e.contains("line 2: z is NaN"), "{e}");
    }
}
