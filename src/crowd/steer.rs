//! Steering on top of the learnt steps (a priori rules, not learnt): walking agents keep within a
//! cone about the direction to their goal, and queueing agents stop on their places in line.

use super::features::unit;
use super::step::{Agent, Planned};

/// Within this distance (units) of its place in a line an agent walks straight to it.
pub const SLOT_APPROACH: f64 = 1.5;

/// An agent in a line walks straight to its place once within [`SLOT_APPROACH`] of it, at its
/// planned speed, and stands there: its step is cut at the place (a model learnt from walkers
/// has no queueing in it, and its locomotion steps would circle the place or carry it past).
/// `queueing[i]`: agent i is in a line (its goal is its place).
pub fn stop_at_places(agents: &[Agent], plans: &mut [Planned], queueing: &[bool], dt: f64) {
    for ((a, p), &q) in agents.iter().zip(plans.iter_mut()).zip(queueing) {
        let Some(g) = a.goal.filter(|_| q) else {
            continue;
        };
        let d = [g[0] - a.pos[0], g[1] - a.pos[1]];
        let dist = d[0].hypot(d[1]);
        if dist > SLOT_APPROACH {
            continue;
        }
        let step = (p.velocity[0].hypot(p.velocity[1]) * dt).min(dist);
        p.velocity = if dist > 0.0 {
            [d[0] / dist * step / dt, d[1] / dist * step / dt]
        } else {
            [0.0, 0.0]
        };
    }
}

/// Turns each steered agent's planned velocity into the cone of half-angle `cone_deg` about the
/// direction to its goal (keeping its speed); agents without a goal, within `near` of it, or
/// with `steer` false, keep theirs. `cone_deg` ≥ 180 does nothing.
pub fn steer_to_goals(
    agents: &[Agent],
    plans: &mut [Planned],
    cone_deg: f64,
    near: f64,
    steer: Vec<bool>,
) {
    if cone_deg >= 180.0 {
        return;
    }
    let cone = cone_deg.to_radians();
    for ((a, p), on) in agents.iter().zip(plans.iter_mut()).zip(steer) {
        let Some(g) = a.goal.filter(|_| on) else {
            continue;
        };
        let d = [g[0] - a.pos[0], g[1] - a.pos[1]];
        if d[0].hypot(d[1]) < near {
            continue;
        }
        let Some(u) = unit(d) else {
            continue;
        };
        let v = p.velocity;
        let speed = v[0].hypot(v[1]);
        if speed <= 0.0 {
            continue;
        }
        // Angle of v from u, in (−π, π].
        let ang = (u[0] * v[1] - u[1] * v[0]).atan2(u[0] * v[0] + u[1] * v[1]);
        if ang.abs() <= cone {
            continue;
        }
        let t = cone.copysign(ang);
        let (c, s) = (t.cos(), t.sin());
        p.velocity = [speed * (u[0] * c - u[1] * s), speed * (u[0] * s + u[1] * c)];
    }
}
