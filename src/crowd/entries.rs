//! Who enters a simulated crowd, where, when and heading where: the entries of real tracks
//! (`crowd simulate --entries`: where and when each individual appeared, where it was last seen
//! and when) and of a layout's spawns, and when each one leaves at the latest.

use super::features::{Scene, V2};
use super::layout::Layout;
use super::model::{toward, CrowdModel};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// An agent entering the scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Entry {
    pub id: u64,
    /// Step at which it appears.
    pub step: usize,
    pub position: V2,
    /// Velocity at entry (units/s).
    pub velocity: V2,
    /// Where it heads for; `None`: it keeps the mean direction of its own past steps and stays
    /// to the end.
    pub goal: Option<V2>,
    /// The step at which it leaves, wherever it is then (the last frame of a real track);
    /// `None`: it leaves on reaching its goal, or when its time is up (`SimConfig::timeout`).
    pub leave: Option<usize>,
}

/// Entries of real tracks: each individual enters where and when it first appeared, moving as it
/// did, heads for where it was last seen and leaves when it was last seen.
pub fn entries_from_tracks(scene: &Scene) -> Vec<Entry> {
    let mut out: Vec<Entry> = scene
        .segments
        .iter()
        .filter(|s| s.pos.len() >= 2)
        .map(|s| Entry {
            id: s.id,
            step: s.start,
            position: s.pos[0],
            velocity: [
                (s.pos[1][0] - s.pos[0][0]) / scene.dt,
                (s.pos[1][1] - s.pos[0][1]) / scene.dt,
            ],
            goal: Some(*s.pos.last().expect("two positions")),
            leave: Some(s.end() - 1),
        })
        .collect();
    // A track split by a gap keeps its id for the first part only.
    out.sort_by_key(|e| (e.id, e.step));
    out.dedup_by_key(|e| e.id);
    out.sort_by_key(|e| (e.step, e.id));
    out
}

/// Entries of a layout's spawns: `count` agents per spawn every `interval` s from `start`,
/// uniformly within `spread` of the entry point, walking toward the goal at `speed`.
pub fn entries_from_layout(layout: &Layout, dt: f64, speed: f64, seed: u64) -> Vec<Entry> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x5a5a_0001);
    let mut out = Vec::new();
    for s in &layout.spawns {
        for c in 0..s.count {
            let t = s.start + c as f64 * s.interval;
            let (r, a) = (
                s.spread * rng.gen::<f64>().sqrt(),
                rng.gen::<f64>() * std::f64::consts::TAU,
            );
            let p = [s.position[0] + r * a.cos(), s.position[1] + r * a.sin()];
            let d = toward(p, Some(s.goal));
            out.push(Entry {
                id: out.len() as u64,
                step: (t / dt).round() as usize,
                position: p,
                velocity: [d[0] * speed, d[1] * speed],
                goal: Some(s.goal),
                leave: None,
            });
        }
    }
    out.sort_by_key(|e| (e.step, e.id));
    out
}

/// The step at which an entry leaves at the latest: after its `leave` step, else when its time
/// is up.
pub(crate) fn deadline(e: &Entry, timeout: f64, dt: f64) -> usize {
    e.leave
        .map_or_else(|| e.step + expected(e, timeout, dt), |l| l.max(e.step) + 1)
}

/// Steps an entry may walk before it times out.
pub(crate) fn expected(e: &Entry, timeout: f64, dt: f64) -> usize {
    let Some(g) = e.goal else {
        return usize::MAX / 4;
    };
    let d = (g[0] - e.position[0]).hypot(g[1] - e.position[1]);
    let v = e.velocity[0].hypot(e.velocity[1]).max(0.3);
    ((timeout * d / v / dt).ceil() as usize).max(10)
}

/// The median step speed of a model's locomotion samples (units/s), for spawned agents.
pub fn typical_speed(model: &CrowdModel) -> f64 {
    let mut v: Vec<f64> = model.behaviours[0]
        .model
        .samples
        .actions
        .iter()
        .map(|a| a[0].hypot(a[1]))
        .collect();
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(1.0)
}

/// Walking groups among `entries` (index-aligned): `Some(key)` for every member of a group of two
/// or more, `key` the id of its leader; `None` for one walking alone or when `distance` is 0.
/// Two entries walk together when they appear at most `steps` apart within `distance` of each
/// other and are last seen (their goals and `leave` steps) as close in time and place. In the
/// order of entry, each one joins the first earlier leader it walks together with (or leads a new
/// group): every member walks together with its leader, so a steady stream does not chain into
/// one group. Only what the entries give a simulation (where and when each one appears and
/// leaves) is used.
pub fn walking_groups(entries: &[Entry], distance: f64, steps: usize) -> Vec<Option<u64>> {
    let n = entries.len();
    let mut out = vec![None; n];
    if distance <= 0.0 {
        return out;
    }
    let near = |a: V2, b: V2| (a[0] - b[0]).hypot(a[1] - b[1]) <= distance;
    let together = |a: &Entry, b: &Entry| match (a.goal, b.goal, a.leave, b.leave) {
        (Some(ga), Some(gb), Some(la), Some(lb)) => {
            b.step <= a.step + steps
                && la.abs_diff(lb) <= steps
                && near(a.position, b.position)
                && near(ga, gb)
        }
        _ => false,
    };
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| (entries[i].step, entries[i].id));
    // Leaders that may still take members (indices into `entries`).
    let mut leaders: Vec<usize> = Vec::new();
    for &j in &order {
        let b = &entries[j];
        // Leaders that entered more than `steps` before take no new members.
        leaders.retain(|&l| entries[l].step + steps >= b.step);
        match leaders.iter().find(|&&l| together(&entries[l], b)) {
            Some(&l) => out[j] = Some(entries[l].id),
            None => leaders.push(j),
        }
    }
    // A leader is grouped only when someone joined it.
    let led: std::collections::HashSet<u64> = out.iter().flatten().copied().collect();
    for (o, e) in out.iter_mut().zip(entries) {
        if led.contains(&e.id) {
            *o = Some(e.id);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(id: u64, step: usize, p: V2, goal: V2, leave: usize) -> Entry {
        Entry {
            id,
            step,
            position: p,
            velocity: [1.0, 0.0],
            goal: Some(goal),
            leave: Some(leave),
        }
    }

    #[test]
    fn walking_groups_join_entries_that_come_and_go_with_the_first_one() {
        let e = vec![
            entry(7, 10, [0.0, 0.0], [10.0, 0.0], 40),
            // Beside 7, one step later, leaving with it: 7's group, led by 7.
            entry(3, 11, [0.0, 0.6], [10.0, 0.7], 41),
            // Beside 3 but 1.4 m from its leader 7: alone (groups do not chain).
            entry(9, 12, [0.0, 1.4], [10.0, 1.5], 40),
            // Enters beside 7 but leaves elsewhere: alone.
            entry(4, 10, [0.3, 0.0], [0.0, 10.0], 40),
            // 7's place and exit, 3 steps after 7: alone (window 2 steps).
            entry(5, 13, [0.0, 0.0], [10.0, 0.0], 40),
            // Same place and exit, leaves 3 steps later: alone.
            entry(6, 10, [0.0, -0.5], [10.0, -0.5], 43),
        ];
        let g = walking_groups(&e, 1.0, 2);
        assert_eq!(g, vec![Some(7), Some(7), None, None, None, None]);
        assert_eq!(walking_groups(&e, 0.0, 2), vec![None; 6]);
        // Without a leave step (a layout's spawns) nobody is grouped.
        let mut spawn = e.clone();
        spawn.iter_mut().for_each(|x| x.leave = None);
        assert_eq!(walking_groups(&spawn, 1.0, 2), vec![None; 6]);
    }
}
