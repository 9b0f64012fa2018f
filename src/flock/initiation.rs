//! Flock initiation (Klotsman & Tal §6): from any start, birds converge to the target shape (the
//! first key shape of the steady flight) by perception (§6.1: the visual volume, Hidden Point
//! Removal, the reference bird) and two drives (§6.2: target reaching with side determination,
//! target distances, speed by eq. 5 and direction by eq. 6; separation).
//!
//! World frame: wingspans, +y the migration direction, a bird's direction d = (sin θ, cos θ)
//! (θ from +y towards +x, the paper's convention); speeds in wingspans per step, one step per
//! output frame, so that eq. 5's √|r − v| and eq. 6's max(r, 1) read as printed.
//!
//! Two additions the paper leaves open, both in `ARCHITECTURE.md`: the leader (front-most bird)
//! and birds that see no flockmate turn towards the migration direction and relax to the cruise
//! speed under the same caps; and **side balancing**: when a side's chain of followers is longer
//! than the target's side while the other side has free places, the rear-most bird beyond the end
//! switches sides and follows the end of the other chain until it reaches its place.

use super::extract::Side;
use super::hpr;
use crate::error::{Error, Result};
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::f64::consts::PI;

/// Settings of the initiation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitiationConfig {
    /// Decisions (and output frames) per second.
    pub fps: f64,
    /// Cruise speed, wingspans/s.
    pub speed: f64,
    /// Visual volume per eye, degrees either side of the heading (the paper: 90°).
    pub eye_field_deg: f64,
    /// Reference-bird volume per eye, degrees (the paper: 0.35π = 63°).
    pub reference_field_deg: f64,
    /// Margin of the HPR flipping sphere beyond the farthest bird, wingspans (the paper's R =
    /// b/2).
    pub hpr_pad: f64,
    /// |K| of eq. 5 (the paper: 0.06).
    pub k: f64,
    /// α of eq. 6 (the paper: 0.2).
    pub alpha: f64,
    /// Separation threshold, wingspans (the paper: 10 b).
    pub separation_distance: f64,
    /// Cap on speed changes, wingspans/s².
    pub max_speed_change: f64,
    /// Cap on turns, degrees/s.
    pub max_turn_deg: f64,
    /// Speed limits as fractions of the cruise speed.
    pub min_speed: f64,
    pub max_speed: f64,
    /// Converged: mean distance to the target positions at most this (wingspans) ...
    pub converge_distance: f64,
    /// ... for this long (seconds).
    pub hold: f64,
    /// Give up after this long (seconds).
    pub max_time: f64,
    /// Random starts: birds uniform in a square of side `start_spread · √N` wingspans ...
    pub start_spread: f64,
    /// ... heading within ± this of the migration direction (degrees), speed 0.8–1.2 × cruise.
    pub start_heading_deg: f64,
}

impl Default for InitiationConfig {
    fn default() -> Self {
        InitiationConfig {
            fps: 25.0,
            speed: 10.0,
            eye_field_deg: 90.0,
            reference_field_deg: 63.0,
            hpr_pad: 0.5,
            k: 0.06,
            alpha: 0.2,
            separation_distance: 10.0,
            max_speed_change: 4.0,
            max_turn_deg: 90.0,
            min_speed: 0.6,
            max_speed: 1.6,
            converge_distance: 0.5,
            hold: 2.0,
            max_time: 60.0,
            start_spread: 3.0,
            start_heading_deg: 60.0,
        }
    }
}

impl InitiationConfig {
    /// Checks the settings; errors name the config key.
    pub fn check(&self) -> Result<()> {
        let positive = [
            ("fps", self.fps),
            ("speed", self.speed),
            ("eye_field_deg", self.eye_field_deg),
            ("reference_field_deg", self.reference_field_deg),
            ("hpr_pad", self.hpr_pad),
            ("alpha", self.alpha),
            ("separation_distance", self.separation_distance),
            ("max_speed_change", self.max_speed_change),
            ("max_turn_deg", self.max_turn_deg),
            ("min_speed", self.min_speed),
            ("converge_distance", self.converge_distance),
            ("max_time", self.max_time),
            ("start_spread", self.start_spread),
        ];
        for (k, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("{k} = {v} must be > 0")));
            }
        }
        if !(self.k.is_finite() && self.k >= 0.0) {
            return Err(Error::invalid(format!("k = {} must be ≥ 0", self.k)));
        }
        if !(self.hold.is_finite() && self.hold >= 0.0) {
            return Err(Error::invalid(format!("hold = {} must be ≥ 0", self.hold)));
        }
        if !(self.max_speed.is_finite() && self.max_speed > self.min_speed) {
            return Err(Error::invalid(format!(
                "max_speed = {} must exceed min_speed = {}",
                self.max_speed, self.min_speed
            )));
        }
        if self.eye_field_deg > 180.0 || self.reference_field_deg > self.eye_field_deg {
            return Err(Error::invalid(format!(
                "reference_field_deg = {} must be within eye_field_deg = {} ≤ 180",
                self.reference_field_deg, self.eye_field_deg
            )));
        }
        if !(0.0..=180.0).contains(&self.start_heading_deg) {
            return Err(Error::invalid(format!(
                "start_heading_deg = {} must be in [0, 180]",
                self.start_heading_deg
            )));
        }
        Ok(())
    }
}

/// One bird's state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Bird {
    /// Position, wingspans.
    pub pos: [f64; 2],
    /// Direction angle θ (d = (sin θ, cos θ)).
    pub theta: f64,
    /// Speed, wingspans per step.
    pub v: f64,
}

impl Bird {
    /// Unit direction.
    pub fn dir(&self) -> [f64; 2] {
        [self.theta.sin(), self.theta.cos()]
    }
}

/// Seeded random start (see [`InitiationConfig::start_spread`]).
pub fn random_start(n: usize, cfg: &InitiationConfig, rng: &mut impl Rng) -> Vec<Bird> {
    let side = cfg.start_spread * (n as f64).sqrt();
    let v = cfg.speed / cfg.fps;
    let h = cfg.start_heading_deg.to_radians();
    (0..n)
        .map(|_| Bird {
            pos: [
                rng.gen_range(-0.5..0.5) * side,
                rng.gen_range(-0.5..0.5) * side,
            ],
            theta: if h > 0.0 { rng.gen_range(-h..=h) } else { 0.0 },
            v: v * rng.gen_range(0.8..1.2),
        })
        .collect()
}

/// The target shape's chains: slot 0 the leader, `nl` left slots from the leader outward, then
/// `nr` right slots.
#[derive(Clone, Debug)]
pub struct Target {
    pub pos: Vec<[f64; 2]>,
    pub nl: usize,
    pub nr: usize,
}

impl Target {
    /// The slot after `t` on side `s` (None beyond the end of the chain).
    pub fn next(&self, t: usize, s: Side) -> Option<usize> {
        let (start, len) = match s {
            Side::Left => (1, self.nl),
            Side::Right => (1 + self.nl, self.nr),
        };
        if t == 0 {
            return (len > 0).then_some(start);
        }
        let rank = t.checked_sub(start).filter(|&r| r < len)?;
        (rank + 1 < len).then_some(t + 1)
    }

    /// The target distance from slot `t` to the bird after it on side `s`; beyond the end of a
    /// chain, the chain's last gap again.
    pub fn delta(&self, t: Option<usize>, next: Option<usize>, s: Side) -> [f64; 2] {
        match (t, next) {
            (Some(a), Some(b)) => [
                self.pos[b][0] - self.pos[a][0],
                self.pos[b][1] - self.pos[a][1],
            ],
            _ => {
                let (start, len) = match s {
                    Side::Left => (1, self.nl),
                    Side::Right => (1 + self.nl, self.nr),
                };
                let sign = if s == Side::Left { -1.0 } else { 1.0 };
                if len == 0 {
                    return [sign, -1.0];
                }
                let end = start + len - 1;
                let prev = if len > 1 { end - 1 } else { 0 };
                let d = [
                    self.pos[end][0] - self.pos[prev][0],
                    self.pos[end][1] - self.pos[prev][1],
                ];
                [sign * d[0].abs(), d[1]]
            }
        }
    }
}

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
    /// Birds switching sides (side balancing), with the side they go to.
    switching: Vec<Option<Side>>,
    /// The current leader (front-most, with a hysteresis of [`LEADER_MARGIN`]).
    leader: Option<usize>,
    /// Steps taken, and the step each switch started.
    steps: usize,
    /// Last step's references: a bird keeps its reference while it stays visible.
    prev_refs: Vec<Option<usize>>,
    switch_since: Vec<usize>,
}

/// A side switch is abandoned after this long (seconds).
pub const SWITCH_TIMEOUT: f64 = 15.0;

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
            switching: vec![None; n],
            leader: None,
            steps: 0,
            prev_refs: vec![None; n],
            switch_since: vec![0; n],
        })
    }

    /// Candidate references of bird `i` in order of preference (§6.1): visible birds within the
    /// reference volume by distance, then the other visible birds by distance.
    fn preferences(&self, i: usize) -> Vec<usize> {
        let b = &self.birds[i];
        let d = b.dir();
        let eye = self.cfg.eye_field_deg.to_radians();
        let refv = self.cfg.reference_field_deg.to_radians();
        let mut cand = Vec::new();
        let mut pts = Vec::new();
        for (j, o) in self.birds.iter().enumerate() {
            if j == i {
                continue;
            }
            let r = [o.pos[0] - b.pos[0], o.pos[1] - b.pos[1]];
            let ang = (d[0] * r[1] - d[1] * r[0])
                .atan2(d[0] * r[0] + d[1] * r[1])
                .abs();
            if ang <= eye && (r[0] != 0.0 || r[1] != 0.0) {
                cand.push((j, ang, r[0].hypot(r[1])));
                pts.push(o.pos);
            }
        }
        let vis = hpr::visible_2d(b.pos, &pts, self.cfg.hpr_pad);
        let mut inner: Vec<(usize, f64)> = Vec::new();
        let mut outer: Vec<(usize, f64)> = Vec::new();
        for (k, &(j, ang, r)) in cand.iter().enumerate() {
            if vis[k] {
                if ang <= refv {
                    inner.push((j, r));
                } else {
                    outer.push((j, r));
                }
            }
        }
        let by = |a: &(usize, f64), b: &(usize, f64)| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0));
        inner.sort_by(by);
        outer.sort_by(by);
        inner.into_iter().chain(outer).map(|(j, _)| j).collect()
    }

    fn leads_to(refs: &[Option<usize>], from: usize, to: usize) -> bool {
        let mut c = Some(from);
        for _ in 0..=refs.len() {
            match c {
                Some(x) if x == to => return true,
                Some(x) => c = refs[x],
                None => return false,
            }
        }
        true
    }

    /// Sides (§6.2.1): a follower of a bird without a side (the leader) takes the side it is on
    /// relative to it; others take their reference's side.
    fn sides(&self, refs: &[Option<usize>], leader: usize) -> Vec<Option<Side>> {
        let n = self.birds.len();
        let mut sides: Vec<Option<Option<Side>>> = vec![None; n];
        sides[leader] = Some(None);
        fn side_of(
            i: usize,
            refs: &[Option<usize>],
            birds: &[Bird],
            switching: &[Option<Side>],
            memo: &mut Vec<Option<Option<Side>>>,
            depth: usize,
        ) -> Option<Side> {
            if let Some(s) = memo[i] {
                return s;
            }
            let s = match (switching[i], refs[i]) {
                (Some(s), _) => Some(s),
                (None, None) => None,
                (None, Some(j)) => {
                    let sj = if depth > refs.len() {
                        None
                    } else {
                        side_of(j, refs, birds, switching, memo, depth + 1)
                    };
                    sj.or(Some(if birds[i].pos[0] > birds[j].pos[0] {
                        Side::Right
                    } else {
                        Side::Left
                    }))
                }
            };
            memo[i] = Some(s);
            s
        }
        (0..n)
            .map(|i| side_of(i, refs, &self.birds, &self.switching, &mut sides, 0))
            .collect()
    }

    /// References after the separation drive (§6.2.2): of two birds following the same bird (on
    /// the same side, for the leader) within `separation_distance` of each other, the rear one
    /// takes its next preference; references that would close a cycle are skipped.
    fn references(&self, leader: usize) -> Vec<Option<usize>> {
        let n = self.birds.len();
        let prefs: Vec<Vec<usize>> = (0..n)
            .map(|i| {
                if i == leader {
                    return vec![];
                }
                let mut p = self.preferences(i);
                // Keep last step's reference first while it is still visible.
                if let Some(j) = self.prev_refs[i] {
                    if let Some(k) = p.iter().position(|&c| c == j) {
                        p.remove(k);
                        p.insert(0, j);
                    }
                }
                p
            })
            .collect();
        let mut pick = vec![0usize; n];
        let mut refs: Vec<Option<usize>> = vec![None; n];
        let choose = |i: usize, pick: &mut Vec<usize>, refs: &mut Vec<Option<usize>>| {
            refs[i] = None;
            while pick[i] < prefs[i].len() {
                let c = prefs[i][pick[i]];
                if !Self::leads_to(refs, c, i) {
                    refs[i] = Some(c);
                    return;
                }
                pick[i] += 1;
            }
        };
        // Front birds choose first, so cycles are broken at their rear-most bird.
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| self.birds[b].pos[1].total_cmp(&self.birds[a].pos[1]));
        for &i in &order {
            if i != leader {
                choose(i, &mut pick, &mut refs);
            }
        }
        for _ in 0..3 * n {
            let sides = self.sides(&refs, leader);
            let mut changed = false;
            for &f in &order {
                let Some(j) = refs[f] else { continue };
                if self.switching[f].is_some() {
                    continue;
                }
                // A bird in front of f with the same reference (and side, at the leader), near.
                let clash = order.iter().take_while(|&&o| o != f).any(|&o| {
                    refs[o] == Some(j)
                        && (j != leader || sides[o] == sides[f])
                        && dist(self.birds[o].pos, self.birds[f].pos)
                            <= self.cfg.separation_distance
                });
                if clash {
                    pick[f] += 1;
                    choose(f, &mut pick, &mut refs);
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        refs
    }

    /// Target slots (§6.2.1 target distances): the leader takes slot 0; a bird whose reference
    /// has a slot takes the next slot on its side.
    fn slots(
        &self,
        refs: &[Option<usize>],
        sides: &[Option<Side>],
        leader: usize,
    ) -> Vec<Option<usize>> {
        let n = self.birds.len();
        let mut slots: Vec<Option<Option<usize>>> = vec![None; n];
        slots[leader] = Some(Some(0));
        for _ in 0..n {
            let mut progress = false;
            for i in 0..n {
                if slots[i].is_some() {
                    continue;
                }
                let (Some(j), Some(s)) = (refs[i], sides[i]) else {
                    continue;
                };
                if let Some(sj) = slots[j] {
                    slots[i] = Some(sj.and_then(|t| self.target.next(t, s)));
                    progress = true;
                }
            }
            if !progress {
                break;
            }
        }
        slots.into_iter().map(|s| s.flatten()).collect()
    }

    /// Side balancing (module docs): starts and ends side switches; returns overridden
    /// references for switching birds.
    fn balance(&mut self, refs: &mut [Option<usize>], leader: usize) {
        let n = self.birds.len();
        let sides = self.sides(refs, leader);
        let slots = self.slots(refs, &sides, leader);
        let mut taken = vec![false; n];
        for t in slots.iter().flatten() {
            taken[*t] = true;
        }
        for s in [Side::Left, Side::Right] {
            let other = if s == Side::Left {
                Side::Right
            } else {
                Side::Left
            };
            // End of the other side's chain: its deepest taken slot's bird.
            let mut end_slot = 0;
            while let Some(nx) = self.target.next(end_slot, other) {
                if !taken[nx] {
                    break;
                }
                end_slot = nx;
            }
            let free = self.target.next(end_slot, other).is_some();
            let end_bird = (0..n)
                .find(|&i| slots[i] == Some(end_slot))
                .unwrap_or(leader);
            // Switching birds already heading there follow the chain's end.
            let mut heading_there = 0;
            for i in 0..n {
                if self.switching[i] == Some(other) {
                    heading_there += 1;
                    refs[i] = Some(end_bird).filter(|&e| e != i);
                }
            }
            let count = |side: Side| sides.iter().filter(|x| **x == Some(side)).count();
            let want = |side: Side| match side {
                Side::Left => self.target.nl,
                Side::Right => self.target.nr,
            };
            if !free || heading_there > 0 || count(s) <= want(s) || count(other) >= want(other) {
                continue;
            }
            // Rear-most bird on side s beyond the end of its chain, followed by nobody.
            let beyond = (0..n)
                .filter(|&i| {
                    i != leader
                        && sides[i] == Some(s)
                        && slots[i].is_none()
                        && refs[i].is_some()
                        && !refs.contains(&Some(i))
                        && self.switching[i].is_none()
                })
                .min_by(|&a, &b| self.birds[a].pos[1].total_cmp(&self.birds[b].pos[1]));
            if let Some(b) = beyond {
                self.switching[b] = Some(other);
                self.switch_since[b] = self.steps;
                refs[b] = Some(end_bird);
            }
        }
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
        self.switching[leader] = None;
        self.steps += 1;
        let timeout = (SWITCH_TIMEOUT * self.cfg.fps) as usize;
        for i in 0..n {
            if self.switching[i].is_some() && self.steps - self.switch_since[i] > timeout {
                self.switching[i] = None;
            }
        }
        let mut refs = self.references(leader);
        self.balance(&mut refs, leader);
        self.prev_refs = refs.clone();
        let sides = self.sides(&refs, leader);
        let slots = self.slots(&refs, &sides, leader);
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
                    let delta = if r > 0.0 {
                        wrap(to[0].atan2(to[1]) - b.theta)
                    } else {
                        0.0
                    };
                    let bd = b.dir();
                    let k = if to[0] * bd[0] + to[1] * bd[1] >= 0.0 {
                        self.cfg.k
                    } else {
                        -self.cfg.k
                    };
                    // Eq. 5 and eq. 6.
                    let v = rb.v * (1.0 - delta.abs() / PI + k * (r - rb.v).abs().sqrt());
                    (v, self.cfg.alpha * delta / r.max(1.0))
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
            // A switching bird that reached its place rejoins the ordinary rules.
            if self.switching[i].is_some() {
                if let (Some(t), Some(_)) = (slots[i], refs[i]) {
                    let want = [
                        self.birds[leader].pos[0] + self.target.pos[t][0] - self.target.pos[0][0],
                        self.birds[leader].pos[1] + self.target.pos[t][1] - self.target.pos[0][1],
                    ];
                    if dist(b.pos, want) < 1.5 {
                        self.switching[i] = None;
                    }
                }
            }
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
