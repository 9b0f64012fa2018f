//! Authoring new herds (paper §7.3–7.5): a scene file places learnt behaviour in a new terrain —
//! obstacles, guidance arrows or a destination, behaviour regions with their parameter sets and
//! speed caps, a spawn — and `herdfit author` simulates it.

pub mod job;
pub mod nav;
pub mod scene;
pub mod sources;

pub use job::{AuthorJob, AuthorSummary};
pub use scene::Scene;

use crate::data::agents::AgentRow;
use crate::error::Result;
use crate::herd::boundary::{Crossings, Inflow, Stream};
use crate::herd::params::N_PARAMS;
use crate::herd::sim::obstacle_map;
use crate::herd::sim::{
    theta_tensor, ForceTensors, Guidance, HerdState, Model, StepDecisions, StepHooks, World,
};
use burn::tensor::Device;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

type P2 = [f64; 2];

/// Time constant (s) with which an agent's parameters follow the region it stands in (§7.4: the
/// force model smooths switches; the ramp avoids a one-step jump).
pub const SWITCH_TIME: f64 = 0.5;

/// The scene's navigation field, one vector per grid cell: the arrows' field with the cancelling
/// field around obstacles, blended with the destination field when there is one.
pub fn navigation(scene: &Scene) -> Vec<P2> {
    let f = &scene.file;
    let arrows = (!f.arrows.is_empty()).then(|| {
        let mut a = nav::arrow_field(
            &scene.grid,
            &scene.obstacles,
            &f.arrows,
            f.navigation.radius,
            f.navigation.decay,
        );
        nav::cancel_obstacles(
            &scene.grid,
            &scene.obstacles,
            &mut a,
            f.navigation.cancel_radius,
        );
        a
    });
    let dest = f.destination.as_ref().map(|d| {
        (
            nav::destination_field(&scene.grid, &scene.obstacles, d.point).0,
            d.weight,
        )
    });
    nav::blend(
        arrows.as_deref(),
        dest.as_ref().map(|(v, w)| (v.as_slice(), *w)),
    )
}

/// Position of the predator at time `t` along its polyline (looping back to the start).
pub fn predator_at(path: &[P2], speed: f64, t: f64) -> P2 {
    let total: f64 = path
        .windows(2)
        .map(|w| (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]))
        .sum();
    if total <= 0.0 {
        return path[0];
    }
    let mut s = (speed * t) % total;
    for w in path.windows(2) {
        let l = (w[1][0] - w[0][0]).hypot(w[1][1] - w[0][1]);
        if s <= l && l > 0.0 {
            let a = s / l;
            return [
                w[0][0] + a * (w[1][0] - w[0][0]),
                w[0][1] + a * (w[1][1] - w[0][1]),
            ];
        }
        s -= l;
    }
    path[path.len() - 1]
}

/// The documented extra-force example (§7.5): flee a predator at `q` within `radius`,
/// F = strength · (1 − d/radius) · (p − q)/d.
pub fn predator_force(pos: &[P2], q: P2, radius: f64, strength: f64) -> Vec<P2> {
    pos.iter()
        .map(|p| {
            let d = (p[0] - q[0]).hypot(p[1] - q[1]);
            if d >= radius || d < 1e-9 {
                [0.0, 0.0]
            } else {
                let k = strength * (1.0 - d / radius) / d;
                [k * (p[0] - q[0]), k * (p[1] - q[1])]
            }
        })
        .collect()
}

/// An authored run.
pub struct AuthorRun {
    pub frames: Vec<Vec<AgentRow>>,
    pub roles: Vec<Vec<bool>>,
    /// Behaviour set of every agent in every frame (0 = default, k = region k − 1).
    pub regions: Vec<Vec<usize>>,
    pub navigation: Vec<P2>,
    pub predator: Vec<P2>,
    /// What entered and left through the scene's boundary, when it declares one.
    pub crossings: Option<Crossings>,
}

fn spawn(scene: &Scene, rng: &mut impl Rng) -> Result<Vec<AgentRow>> {
    let s = &scene.file.spawn;
    let speed = &scene.params[0].speed;
    let mut rows = Vec::with_capacity(s.count);
    let mut tries = 0usize;
    while rows.len() < s.count {
        tries += 1;
        if tries > 1000 * s.count + 1000 {
            return Err(crate::Error::file(
                &scene.path,
                "spawn: its rectangle is covered by obstacles",
            ));
        }
        let p = [
            s.centre[0] + (rng.gen::<f64>() - 0.5) * s.size[0],
            s.centre[1] + (rng.gen::<f64>() - 0.5) * s.size[1],
        ];
        if scene.blocked(p) {
            continue;
        }
        let z: f64 = rng.sample(StandardNormal);
        let a = (s.heading_deg + 15.0 * z).to_radians();
        let zs: f64 = rng.sample(StandardNormal);
        let v = (speed.mean + speed.std * zs).clamp(0.0, speed.max);
        rows.push(AgentRow {
            id: rows.len() as u64,
            x: p[0],
            y: p[1],
            vx: v * a.cos(),
            vy: v * a.sin(),
        });
    }
    Ok(rows)
}

/// What an authored run changes between steps: each agent's parameter set ramps towards its
/// region's, the predator's force is added, and after the step speeds are capped per region
/// and no agent enters an obstacle.
struct SceneHooks<'a, P: FnMut()> {
    scene: &'a Scene,
    device: &'a Device,
    dt: f64,
    ramp: f64,
    sets: Vec<[f64; N_PARAMS]>,
    /// Each agent's current parameters and behaviour set.
    thetas: Vec<[f64; N_PARAMS]>,
    ids: Vec<u64>,
    frames: Vec<Vec<AgentRow>>,
    roles: Vec<Vec<bool>>,
    regions: Vec<Vec<usize>>,
    predator: Vec<P2>,
    progress: &'a mut P,
    /// The scene's sources and sinks, when it declares them.
    stream: Option<Stream<'a>>,
}

impl<P: FnMut()> StepHooks for SceneHooks<'_, P> {
    fn forces(&mut self, _t: usize, _state: &HerdState) -> Result<Option<ForceTensors>> {
        let region = self.regions.last().map(Vec::as_slice).unwrap_or(&[]);
        for (th, &r) in self.thetas.iter_mut().zip(region) {
            for (a, b) in th.iter_mut().zip(&self.sets[r]) {
                *a += (b - *a) * self.ramp;
            }
        }
        let c = &self.scene.params[0].constants;
        Ok(Some(ForceTensors::per_agent(&self.thetas, c, self.device)))
    }

    fn extra(&mut self, t: usize, state: &HerdState) -> Result<Option<Vec<P2>>> {
        let Some(p) = &self.scene.file.predator else {
            return Ok(None);
        };
        let q = predator_at(&p.path, p.speed, t as f64 * self.dt);
        self.predator.push(q);
        let pos = state.snapshot()?.pos;
        Ok(Some(predator_force(&pos, q, p.radius, p.strength)))
    }

    fn after(&mut self, _t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState> {
        self.roles.push(dec.leader.clone());
        let (scene, dt) = (self.scene, self.dt);
        let old_rows = self.frames.last().map(Vec::as_slice).unwrap_or(&[]);
        let mut rows = next.rows(&self.ids)?;
        for (r, old) in rows.iter_mut().zip(old_rows) {
            // An entrant still outside the world walks in; one leaving through an exit walks out
            // (the boundary removes it below).
            if scene.grid.cell_of([old.x, old.y]).is_none()
                || scene.exits_at([old.x, old.y], [r.x, r.y])
            {
                continue;
            }
            // Speed cap of the region the agent stands in.
            let v = r.vx.hypot(r.vy);
            if let Some(cap) = scene.speed_cap_at([old.x, old.y]) {
                if v > cap {
                    let s = cap / v;
                    r.vx *= s;
                    r.vy *= s;
                    r.x = old.x + r.vx * dt;
                    r.y = old.y + r.vy * dt;
                }
            }
            // Never into an obstacle: slide along x or y, or stay.
            if scene.blocked([r.x, r.y]) {
                if !scene.blocked([r.x, old.y]) {
                    r.y = old.y;
                } else if !scene.blocked([old.x, r.y]) {
                    r.x = old.x;
                } else {
                    r.x = old.x;
                    r.y = old.y;
                }
            }
        }
        if let Some(stream) = &mut self.stream {
            let ids = std::mem::take(&mut self.ids);
            let old: std::collections::HashMap<u64, [f64; N_PARAMS]> = ids
                .iter()
                .copied()
                .zip(self.thetas.iter().copied())
                .collect();
            let mut kept = ids;
            rows = crate::herd::boundary::edit_rows(rows, |a| {
                let changed = stream.apply(self.frames.len(), dt, a);
                kept = a.ids.clone();
                changed
            });
            // Each agent keeps its parameters; a new one takes its region's set.
            self.thetas = rows
                .iter()
                .map(|r| {
                    old.get(&r.id)
                        .copied()
                        .unwrap_or(self.sets[scene.region_at([r.x, r.y])])
                })
                .collect();
            self.ids = kept;
        }
        let state = HerdState::from_rows(&rows, self.device);
        self.regions
            .push(rows.iter().map(|r| scene.region_at([r.x, r.y])).collect());
        self.frames.push(rows);
        (self.progress)();
        Ok(state)
    }
}

/// Simulates a scene. Leaders follow the navigation field; every agent uses the parameter set of
/// the region it stands in (ramped over [`SWITCH_TIME`]); speeds are capped per region; a step
/// that would put an agent inside an obstacle (or outside the world) slides along the wall or
/// stays, so no agent centre is ever inside an obstacle.
pub fn run(scene: &Scene, device: &Device, mut progress: impl FnMut()) -> Result<AuthorRun> {
    let f = &scene.file;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(f.seed);
    let rows = spawn(scene, &mut rng)?;
    let navf = navigation(scene);
    let g = scene.grid;
    let g_grid = g;
    let model = Model {
        params: scene.params[0].clone(),
        world: World {
            obstacles: Some(obstacle_map(&g, &scene.obstacles)),
            guidance: Guidance::Field {
                origin: g.origin,
                cell_size: g.cell_size,
                nx: g.nx,
                ny: g.ny,
                dirs: navf.clone(),
            },
            fixed_speed: None,
        },
        dt: 1.0 / f.fps,
        force_kernel: crate::herd::sim::ForceKernel::default(),
    };
    let sets: Vec<[f64; N_PARAMS]> = scene.params.iter().map(|p| p.to_vec()).collect();
    let region: Vec<usize> = rows.iter().map(|r| scene.region_at([r.x, r.y])).collect();
    let steps = (f.duration * f.fps).round().max(1.0) as usize;
    let mut hooks = SceneHooks {
        scene,
        device,
        dt: model.dt,
        ramp: (model.dt / SWITCH_TIME).min(1.0),
        thetas: region.iter().map(|&k| sets[k]).collect(),
        sets,
        ids: rows.iter().map(|r| r.id).collect(),
        frames: vec![rows.clone()],
        roles: Vec::with_capacity(steps + 1),
        regions: vec![region],
        predator: Vec::new(),
        progress: &mut progress,
        stream: None,
    };
    let gates = f.boundary.as_ref().map(|b| b.gates());
    if let (Some(b), Some(g)) = (&f.boundary, &gates) {
        let inflow = Inflow::Scene {
            grid: g_grid,
            heading: &navf,
            count: b.count,
            rate: b.rate.unwrap_or(0.0),
        };
        let next_id = rows.len() as u64;
        hooks.stream = Some(Stream::of(
            inflow,
            g,
            model.params.speed.clone(),
            f.seed,
            next_id,
        ));
    }
    // The set-up θ is unused: every step takes the per-agent sets of [`SceneHooks::forces`].
    let theta = theta_tensor(&hooks.sets[0], device);
    let state = model.run_live(&theta, &rows, steps, &mut rng, &mut hooks)?;
    let crossings = hooks.stream.map(|s| s.crossings);
    let (frames, mut roles, regions, predator) =
        (hooks.frames, hooks.roles, hooks.regions, hooks.predator);
    roles.push(model.decide(&state.snapshot()?, &mut rng).leader);
    Ok(AuthorRun {
        frames,
        roles,
        regions,
        navigation: navf,
        predator,
        crossings,
    })
}
