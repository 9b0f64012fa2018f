//! The herd's agent-row CSV formats: `INIT.csv` (`id,x,y,vx,vy`, an initial herd) and the
//! trajectory CSV `frame,time,id,x,y,vx,vy,role` written by `simulate`, `synth` and `author` (a
//! `herdfit.tracks/1` file without sidecar, see [`crate::data::tracks`]).

use crate::error::{Error, Result};
use std::path::Path;

/// One agent of an initial-state or trajectory file: position (BL) and velocity (BL/s).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgentRow {
    pub id: u64,
    pub x: f64,
    pub y: f64,
    pub vx: f64,
    pub vy: f64,
}

/// Reads `id,x,y,vx,vy` rows (header required, columns in any order, extra columns ignored).
pub fn read_init_csv(path: &Path) -> Result<Vec<AgentRow>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let Some((_, header)) = lines.next() else {
        return Err(Error::file(
            path,
            "empty file (expected header id,x,y,vx,vy)",
        ));
    };
    let cols: Vec<&str> = header.split(',').map(str::trim).collect();
    let find = |name: &str| -> Result<usize> {
        cols.iter()
            .position(|c| *c == name)
            .ok_or_else(|| Error::file(path, format!("header lacks column '{name}'")))
    };
    let idx = [
        find("id")?,
        find("x")?,
        find("y")?,
        find("vx")?,
        find("vy")?,
    ];
    let mut rows = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for (ln, line) in lines {
        let f: Vec<&str> = line.split(',').map(str::trim).collect();
        let line_no = ln + 1;
        let get = |k: usize, name: &str| -> Result<&str> {
            f.get(idx[k]).copied().ok_or_else(|| {
                Error::file(path, format!("line {line_no}: missing column '{name}'"))
            })
        };
        let num = |k: usize, name: &str| -> Result<f64> {
            let s = get(k, name)?;
            let v: f64 = s.parse().map_err(|_| {
                Error::file(
                    path,
                    format!("line {line_no}: {name} = '{s}' is not a number"),
                )
            })?;
            if !v.is_finite() {
                return Err(Error::file(path, format!("line {line_no}: {name} is {v}")));
            }
            Ok(v)
        };
        let id_s = get(0, "id")?;
        let id: u64 = id_s.parse().map_err(|_| {
            Error::file(
                path,
                format!("line {line_no}: id = '{id_s}' is not a non-negative integer"),
            )
        })?;
        if !seen.insert(id) {
            return Err(Error::file(
                path,
                format!("line {line_no}: duplicate id {id}"),
            ));
        }
        rows.push(AgentRow {
            id,
            x: num(1, "x")?,
            y: num(2, "y")?,
            vx: num(3, "vx")?,
            vy: num(4, "vy")?,
        });
    }
    if rows.is_empty() {
        return Err(Error::file(path, "no agents (empty herd)"));
    }
    Ok(rows)
}

/// Header of trajectory files.
pub const TRAJ_HEADER: &str = "frame,time,id,x,y,vx,vy,role";

/// Appends one frame of a trajectory CSV. Values are written in Rust's shortest round-trip form,
/// so the bytes depend only on the values.
pub fn push_traj_frame(
    out: &mut String,
    frame: usize,
    time: f64,
    rows: &[AgentRow],
    leader: &[bool],
) {
    use std::fmt::Write as _;
    for (r, &l) in rows.iter().zip(leader) {
        let role = if l { "leader" } else { "follower" };
        let _ = writeln!(
            out,
            "{frame},{time},{},{},{},{},{},{role}",
            r.id, r.x, r.y, r.vx, r.vy
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn init_csv_parses_and_names_bad_lines() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("init.csv");
        std::fs::write(&p, "id,x,y,vx,vy\n0,1,2,0.5,0\n7,-1,2.5,0,-1\n").unwrap();
        let rows = read_init_csv(&p).unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].id, 7);
        assert_eq!(rows[1].vy, -1.0);
        std::fs::write(&p, "id,x,y,vx,vy\n0,1,2,0.5,0\n1,1,zz,0,0\n").unwrap();
        let e = read_init_csv(&p).unwrap_err().to_string();
        assert!(e.contains("line 3") && e.contains("y = 'zz'"), "{e}");
        std::fs::write(&p, "id,x,y,vx,vy\n0,1,NaN,0.5,0\n").unwrap();
        assert!(read_init_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("y is NaN"));
        std::fs::write(&p, "id,x,y,vx\n0,1,2,0.5\n").unwrap();
        assert!(read_init_csv(&p).unwrap_err().to_string().contains("'vy'"));
        std::fs::write(&p, "id,x,y,vx,vy\n").unwrap();
        assert!(read_init_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("empty herd"));
        std::fs::write(&p, "id,x,y,vx,vy\n1,0,0,0,0\n1,1,1,0,0\n").unwrap();
        assert!(read_init_csv(&p)
            .unwrap_err()
            .to_string()
            .contains("duplicate id 1"));
    }
}
