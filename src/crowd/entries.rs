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
