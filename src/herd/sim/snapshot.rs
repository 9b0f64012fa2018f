//! A plain copy of a herd state (paper §5: positions, headings, speeds), read back from the
//! device or built from agent rows.

use crate::data::agents::AgentRow;
use herdfit_kernels::P2;

/// Plain copy of a state, read back from the device.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    pub pos: Vec<P2>,
    pub head: Vec<P2>,
    pub speed: Vec<f64>,
}

impl Snapshot {
    /// The state of agent rows: velocity gives heading and speed (a standing agent faces +x).
    pub fn of_rows(rows: &[AgentRow]) -> Self {
        let mut head = Vec::with_capacity(rows.len());
        let mut speed = Vec::with_capacity(rows.len());
        for r in rows {
            let s = (r.vx * r.vx + r.vy * r.vy).sqrt();
            head.push(if s > 1e-12 {
                [r.vx / s, r.vy / s]
            } else {
                [1.0, 0.0]
            });
            speed.push(s);
        }
        Snapshot {
            pos: rows.iter().map(|r| [r.x, r.y]).collect(),
            head,
            speed,
        }
    }

    /// Agent rows (velocity = speed · heading) with the given ids.
    pub fn rows(&self, ids: &[u64]) -> Vec<AgentRow> {
        (0..self.pos.len())
            .map(|i| AgentRow {
                id: ids[i],
                x: self.pos[i][0],
                y: self.pos[i][1],
                vx: self.speed[i] * self.head[i][0],
                vy: self.speed[i] * self.head[i][1],
            })
            .collect()
    }
}
