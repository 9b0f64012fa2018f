//! Flock initiation (Klotsman & Tal §6): from any start, birds converge to the target shape (the
//! first key shape of the steady flight) by perception (§6.1: the visual volume, Hidden Point
//! Removal, the reference bird) and two drives (§6.2: target reaching with side determination,
//! target distances, speed by eq. 5 and direction by eq. 6; separation).
//!
//! World frame: wingspans, +y the migration direction, a bird's direction d = (sin θ, cos θ)
//! (θ from +y towards +x, the paper's convention); speeds in wingspans per step, one step per
//! output frame, so that eq. 5's √|r − v| and eq. 6's max(r, 1) read as printed.
//!
//! Rules the paper leaves open or that it needs to converge (all in `ARCHITECTURE.md`,
//! "Initiation additions" and "the chain rules"): the leader (front-most bird) and birds without
//! a reference turn towards the migration direction at the cruise speed; eq. 6 steers at a point
//! `look_ahead` beyond the target along the migration direction; K's sign in eq. 5 is + while the
//! bird is behind its place; and the **chain rules**: a bird is followed by at most one bird (the
//! leader by one per side) at any distance — of two, the rear one chooses again (§6.2.2 without
//! its 10 b threshold) —, a bird keeps its reference while it sees it (hysteresis), a follower of
//! the leader keeps its side, a bird chooses only a reference matched to the target shape with a
//! free place behind it on its side, and one that finds none in its visual volume searches all
//! round.

mod perception;
mod setup;

pub use setup::{random_start, Bird, InitiationConfig, Target};

use super::extract::Side;
use crate::error::{Error, Result};
use serde::Serialize;
use std::f64::consts::PI;

/// What one step decided (for tests and reports).
#[derive(Clone, Debug, Default)]
pub struct Decisions {
    pub leader: usize,
    pub refs: Vec<Option<usize>>,
    pub sides: Vec<Option<Side>>,
    /// Target slot of each bird (None: unmatched or beyond a chain's end).
    pub slots: Vec<Option<usize>>,
    /// Mean distance to the target positions when the slots are a bijection.
    pub mean_error: Option<f64>,
}

/// The initiation state.
pub struct Initiation {
    pub cfg: InitiationConfig,
    pub target: Target,
    pub birds: Vec<Bird>,
    /// The current leader (front-most, with a hysteresis of [`LEADER_MARGIN`]).
    leader: Option<usize>,
    /// Last step's references and sides (the hysteresis of the chain rules).
    prev_refs: Vec<Option<usize>>,
    prev_sides: Vec<Option<Side>>,
}

/// Another bird takes the lead only once it is this far (wingspans) ahead of the leader, so a
/// follower overshooting its place does not flip the leadership back and forth.
pub const LEADER_MARGIN: f64 = 2.0;

fn wrap(a: f64) -> f64 {
    let mut a = (a + PI).rem_euclid(2.0 * PI) - PI;
    if a <= -PI {
        a += 2.0 * PI;
    }
    a
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

impl Initiation {
    /// A new initiation towards `target` from `birds`.
    pub fn new(cfg: InitiationConfig, target: Target, birds: Vec<Bird>) -> Result<Self> {
        cfg.check()?;
        if birds.len() != target.pos.len() {
            return Err(Error::invalid(format!(
                "{} birds for a target shape of {}",
                birds.len(),
                target.pos.len()
            )));
        }
        let n = birds.len();
        Ok(Initiation {
            cfg,
            target,
            birds,
            leader: None,
            prev_refs: vec![None; n],
            prev_sides: vec![None; n],
        })
    }

    /// One time step; returns what was decided.
    pub fn step(&mut self) -> Decisions {
        let n = self.birds.len();
        let front = (0..n)
            .max_by(|&a, &b| {
                self.birds[a].pos[1]
                    .total_cmp(&self.birds[b].pos[1])
                    .then(b.cmp(&a))
            })
            .unwrap_or(0);
        let leader = match self.leader {
            Some(l) if self.birds[front].pos[1] - self.birds[l].pos[1] < LEADER_MARGIN => l,
            _ => front,
        };
        self.leader = Some(leader);
        let (refs, sides, slots) = self.references(leader);
        self.prev_refs = refs.clone();
        self.prev_sides = sides.clone();
        let mean_error = self.mean_error(&slots, leader);
        let cruise = self.cfg.speed / self.cfg.fps;
        let dv = self.cfg.max_speed_change / (self.cfg.fps * self.cfg.fps);
        let dth = self.cfg.max_turn_deg.to_radians() / self.cfg.fps;
        let mut next = self.birds.clone();
        for i in 0..n {
            let b = self.birds[i];
            let (mut v, mut dtheta) = match (i == leader, refs[i], sides[i]) {
                (false, Some(j), Some(s)) => {
                    let rb = self.birds[j];
                    let d = self.target.delta(slots[j], slots[i], s);
                    let pj = [
                        rb.pos[0] + rb.v * rb.dir()[0],
                        rb.pos[1] + rb.v * rb.dir()[1],
                    ];
                    let t = [pj[0] + d[0], pj[1] + d[1]];
                    let to = [t[0] - b.pos[0], t[1] - b.pos[1]];
                    let r = to[0].hypot(to[1]);
                    // Steer at a point `look_ahead` beyond the target along the reference's
                    // direction (the distance r and K's sign stay the target's).
                    let rd = rb.dir();
                    let la = self.cfg.look_ahead;
                    let aim = [to[0], to[1] + la];
                    let delta = if aim[0] != 0.0 || aim[1] != 0.0 {
                        wrap(aim[0].atan2(aim[1]) - b.theta)
                    } else {
                        0.0
                    };
                    // K's sign (eq. 5): + while the bird is behind its place, i.e. the target
                    // (one step of the reference ahead of the place) lies more than that step
                    // ahead along the reference's direction.
                    let k = if to[0] * rd[0] + to[1] * rd[1] >= rb.v {
                        self.cfg.k
                    } else {
                        -self.cfg.k
                    };
                    // Eq. 5 and eq. 6.
                    let v = rb.v * (1.0 - delta.abs() / PI + k * (r - rb.v).abs().sqrt());
                    (
                        v,
                        self.cfg.alpha * delta / r.clamp(1.0, self.cfg.turn_distance.max(1.0)),
                    )
                }
                _ => (cruise, self.cfg.alpha * wrap(-b.theta)),
            };
            v = v.clamp(b.v - dv, b.v + dv);
            v = v.clamp(self.cfg.min_speed * cruise, self.cfg.max_speed * cruise);
            dtheta = dtheta.clamp(-dth, dth);
            let theta = wrap(b.theta + dtheta);
            let d = [theta.sin(), theta.cos()];
            next[i] = Bird {
                pos: [b.pos[0] + v * d[0], b.pos[1] + v * d[1]],
                theta,
                v,
            };
        }
        self.birds = next;
        Decisions {
            leader,
            refs,
            sides,
            slots,
            mean_error,
        }
    }

    /// Mean distance of the birds to their target positions (the target shape placed at the
    /// leader), when every bird has a distinct slot.
    pub fn mean_error(&self, slots: &[Option<usize>], leader: usize) -> Option<f64> {
        let n = self.birds.len();
        let mut seen = vec![false; n];
        let mut sum = 0.0;
        let l = self.birds[leader].pos;
        for (i, s) in slots.iter().enumerate() {
            let t = (*s)?;
            if seen[t] {
                return None;
            }
            seen[t] = true;
            let want = [
                l[0] + self.target.pos[t][0] - self.target.pos[0][0],
                l[1] + self.target.pos[t][1] - self.target.pos[0][1],
            ];
            sum += dist(self.birds[i].pos, want);
        }
        Some(sum / n as f64)
    }
}

/// Outcome of a whole initiation run.
#[derive(Clone, Debug, Serialize)]
pub struct InitiationRun {
    /// Bird states per step (step 0 = the start).
    #[serde(skip)]
    pub frames: Vec<Vec<Bird>>,
    /// Seconds until the mean distance stayed within `converge_distance` for `hold` (None: it
    /// did not within `max_time`).
    pub converged_after: Option<f64>,
    /// At the end: mean distance to the targets, closest pair, most followers of a non-leader,
    /// and each bird's target slot.
    pub final_mean_error: Option<f64>,
    pub min_pair_distance: f64,
    pub max_followers: usize,
    #[serde(skip)]
    pub slots: Vec<Option<usize>>,
}

/// Runs the initiation until it converges (and holds) or `max_time` passes.
pub fn run(mut sim: Initiation) -> InitiationRun {
    let fps = sim.cfg.fps;
    let max_steps = (sim.cfg.max_time * fps).ceil() as usize;
    let hold_steps = (sim.cfg.hold * fps).round() as usize;
    let mut frames = vec![sim.birds.clone()];
    let mut run_len = 0usize;
    let mut last = Decisions::default();
    let mut converged_after = None;
    for step in 1..=max_steps {
        last = sim.step();
        frames.push(sim.birds.clone());
        match last.mean_error {
            Some(e) if e <= sim.cfg.converge_distance => run_len += 1,
            _ => run_len = 0,
        }
        if run_len > hold_steps {
            converged_after = Some(step as f64 / fps);
            break;
        }
    }
    let n = sim.birds.len();
    let mut min_pair = f64::INFINITY;
    for i in 0..n {
        for j in i + 1..n {
            min_pair = min_pair.min(dist(sim.birds[i].pos, sim.birds[j].pos));
        }
    }
    let mut followers = vec![0usize; n];
    for r in last.refs.iter().flatten() {
        followers[*r] += 1;
    }
    let max_followers = (0..n)
        .filter(|&i| i != last.leader)
        .map(|i| followers[i])
        .max()
        .unwrap_or(0);
    let final_mean_error = sim.mean_error(&last.slots, last.leader);
    InitiationRun {
        frames,
        converged_after,
        final_mean_error,
        min_pair_distance: min_pair,
        max_followers,
        slots: last.slots,
    }
}
