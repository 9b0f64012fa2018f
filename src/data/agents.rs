//! The herd's agent-row CSV formats: `INIT.csv` (`id,x,y,vx,vy`, an initial herd) and the
//! trajectory CSV `frame,time,id,x,y,vx,vy,role` written by `simulate`, `synth` and `author` (a
//! `herdfit.tracks/1` file without sidecar, see [`crate::data::tracks`]).

use crate::data::csv::Table;
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
    crate::data::atomic::note_input(path);
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let table = Table::parse(path, &text, "id,x,y,vx,vy")?;
    let idx = [
        table.need("id")?,
        table.need("x")?,
        table.need("y")?,
        table.need("vx")?,
        table.need("vy")?,
    ];
    let mut rows = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for r in table.records() {
        let line_no = r.line();
        let id = r.int(idx[0], "id")?;
        if !seen.insert(id) {
            return Err(Error::file(
                path,
                format!("line {line_no}: duplicate id {id}"),
            ));
        }
        let row = AgentRow {
            id,
            x: r.num(idx[1], "x")?,
            y: r.num(idx[2], "y")?,
            vx: r.num(idx[3], "vx")?,
            vy: r.num(idx[4], "vy")?,
        };
        if let Some(m) = out_of_range(&row) {
            return Err(Error::file(path, format!("line {line_no}: {m}")));
        }
        crate::limits::check_count("agents", rows.len() + 1, crate::limits::MAX_AGENTS)
            .map_err(|e| e.in_file(path))?;
        rows.push(row);
    }
    if rows.is_empty() {
        return Err(Error::file(path, "no agents (empty herd)"));
    }
    Ok(rows)
}

/// The first value of `row` that is not finite or lies beyond the limits (positions
/// ±[`MAX_COORD`](crate::limits::MAX_COORD), velocities ±[`MAX_SPEED`](crate::limits::MAX_SPEED)),
/// as "key = value is beyond ±max".
pub fn out_of_range(row: &AgentRow) -> Option<String> {
    use crate::limits::{MAX_COORD, MAX_SPEED};
    [
        ("x", row.x, MAX_COORD),
        ("y", row.y, MAX_COORD),
        ("vx", row.vx, MAX_SPEED),
        ("vy", row.vy, MAX_SPEED),
    ]
    .into_iter()
    .find(|(_, v, max)| !(v.is_finite() && v.abs() <= *max))
    .map(|(key, v, max)| format!("{key} = {v} is beyond ±{max}"))
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
        let file = tempfile::NamedTempFile::new().unwrap();
        let read = |text: &str| {
            std::fs::write(file.path(), text).unwrap();
            read_init_csv(file.path())
        };
        let rows = read("id,x,y,vx,vy\n0,1,2,0.5,0\n7,-1,2.5,0,-1\n").unwrap();
        assert_eq!(rows.len(), 2);
        assert_eq!(rows[1].id, 7);
        assert_eq!(rows[1].vy, -1.0);
        let error = |text: &str| read(text).unwrap_err().to_string();
        let e = error("id,x,y,vx,vy\n0,1,2,0.5,0\n1,1,zz,0,0\n");
        assert!(e.contains("line 3") && e.contains("y = 'zz'"), "{e}");
        assert!(error("id,x,y,vx,vy\n0,1,NaN,0.5,0\n").contains("y is NaN"));
        assert!(error("id,x,y,vx\n0,1,2,0.5\n").contains("'vy'"));
        assert!(error("id,x,y,vx,vy\n").contains("empty herd"));
        assert!(error("id,x,y,vx,vy\n1,0,0,0,0\n1,1,1,0,0\n").contains("duplicate id 1"));
    }
}
