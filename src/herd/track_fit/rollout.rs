//! One window of a track fit: the animals tracked at its start, stepped by the model (eq. 2–6,
//! the fused force op of eq. 3–5 on autodiff devices) for the window's steps, either among
//! their neighbours replayed from the tracks ([`Rollout::Conditioned`]) or jointly
//! ([`Rollout::Free`]).
//!
//! A window starting at frame f₀ rolls out every animal tracked in f₀ and f₀ − 1, from its
//! tracked position and its velocity (p(f₀) − p(f₀ − 1))/Δt — read without looking past f₀.
//! Leaders (§5.1) follow the guidance field of the last frame whose field the clip computed
//! from frames up to f₀ (f₀ − 1 − ⌊w/2⌋ for a velocity window of w frames), held for the
//! window: never an animal's own future.
//!
//! The neighbour-conditioned step simulates the animals side by side with the tracked scene:
//! the state is the window's animals followed by the scene (every animal tracked in the step's
//! frame, constants), and each simulated animal perceives the scene alone, its own tracked twin
//! left out ([`perceive_among`]); the scene's rows perceive nothing and are dropped after the
//! step. So the model's own step and fused force op run unchanged, and the gradient reaches θ
//! through each animal's own path only.

use super::config::{Rollout, Scoring, Speeds};
use super::data::TrackSet;
use super::spacing::{spacing_sq, Neighbours};
use crate::data::agents::AgentRow;
use crate::error::{Error, Result};
use crate::herd::sim::{
    read_vec, Decide, ForceTensors, Guidance, HerdState, Model, Snapshot, StepDecisions,
};
use burn::tensor::{Device, Tensor, TensorData};
use herdfit_kernels::{perceive_among, Perception, Scene, P2};
use rand::Rng;
use rand_distr::StandardNormal;
use std::ops::Range;

/// One clip's tracks and the model that steps them.
#[derive(Clone, Debug)]
pub struct TrackClip {
    /// A name for reports (the clip folder or the tracks file).
    pub name: String,
    pub tracks: TrackSet,
    /// Obstacles, time step and parameters (the speed model included); its guidance is set per
    /// window.
    pub model: Model,
    /// The leaders' guidance of every clip frame (empty: no leaders).
    pub guidance: Vec<Guidance>,
    /// Frames the clip's velocity at a frame reaches ahead (⌊w/2⌋ + 1 for a velocity window of
    /// w frames computed by central differences; 0 for a simulation's own velocities).
    pub lookahead: usize,
    /// Frames learnt from or scored.
    pub frames: Range<usize>,
}

/// A window: clip, start frame f₀, steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    pub clip: usize,
    pub start: usize,
    pub steps: usize,
}

impl TrackClip {
    /// The guidance a window starting at `f0` follows: the clip's field of the last frame whose
    /// velocities end by `f0`.
    pub fn guidance_for(&self, f0: usize) -> Guidance {
        f0.checked_sub(self.lookahead)
            .and_then(|g| self.guidance.get(g))
            .cloned()
            .unwrap_or(Guidance::None)
    }

    /// The animals a window starting at `f0` rolls out: tracked in `f0` and `f0 − 1`, with their
    /// velocity into `f0`, ordered by id.
    pub fn starters(&self, f0: usize) -> Vec<AgentRow> {
        let t = &self.tracks;
        t.at(f0)
            .iter()
            .filter_map(|a| {
                let v = t.back_vel(f0, a.id)?;
                Some(AgentRow {
                    id: a.id,
                    x: a.pos[0],
                    y: a.pos[1],
                    vx: v[0],
                    vy: v[1],
                })
            })
            .collect()
    }

    /// The windows of `steps` steps starting at `offset` past the first startable frame, every
    /// `stride` frames, cut at the end of the frames; only those with an animal to roll out.
    pub fn windows(&self, index: usize, steps: usize, stride: usize, offset: usize) -> Vec<Window> {
        let (a, b) = (self.frames.start, self.frames.end.min(self.tracks.len()));
        let mut out = Vec::new();
        let mut f0 = a + 1 + offset;
        while f0 + 1 < b {
            if self
                .tracks
                .at(f0)
                .iter()
                .any(|x| self.tracks.back_vel(f0, x.id).is_some())
            {
                out.push(Window {
                    clip: index,
                    start: f0,
                    steps: steps.min(b - 1 - f0),
                });
            }
            f0 += stride.max(1);
        }
        out
    }
}

fn vec_tensor(v: Vec<f64>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

/// The decisions of one neighbour-conditioned step for `nf` simulated animals (rows `0..nf`,
/// perceiving the scene of rows `nf..`): the scene's perception of them (indices shifted past
/// the simulated rows), roles by the leader rule (§5.1) with `model`'s guidance, and ξ.
fn conditioned_decisions(
    model: &Model,
    me: &Snapshot,
    own: &[Option<u32>],
    scene: Scene<'_>,
    rng: &mut impl Rng,
) -> StepDecisions {
    let nf = me.pos.len();
    let ns = scene.pos.len();
    let q = Scene {
        pos: &me.pos,
        head: &me.head,
    };
    let p = perceive_among(
        q,
        own,
        scene,
        model.world.obstacles.as_ref(),
        &model.perception_config(),
    );
    let n = nf + ns;
    let (k, ko) = (p.k, p.ko);
    let mut c = Perception {
        n,
        k,
        neighbours: (0..n as u32)
            .flat_map(|i| std::iter::repeat_n(i, k))
            .collect(),
        neighbour_mask: vec![0; n * k],
        neighbour_branch: vec![0; n * k],
        ko,
        obstacle_points: Vec::with_capacity(n * ko),
        obstacle_mask: vec![0; n * ko],
        obstacle_branch: vec![0; n * ko],
        front_count: p.front_count.clone(),
        density: p.density.clone(),
    };
    for i in 0..nf {
        for s in 0..k {
            let e = i * k + s;
            if p.neighbour_mask[e] == 1 {
                c.neighbours[e] = p.neighbours[e] + nf as u32;
                c.neighbour_mask[e] = 1;
                c.neighbour_branch[e] = p.neighbour_branch[e];
            }
        }
    }
    c.obstacle_points.extend_from_slice(&p.obstacle_points);
    c.obstacle_points
        .extend(scene.pos.iter().flat_map(|&q| std::iter::repeat_n(q, ko)));
    c.obstacle_mask[..nf * ko].copy_from_slice(&p.obstacle_mask);
    c.obstacle_branch[..nf * ko].copy_from_slice(&p.obstacle_branch);
    c.front_count.resize(n, 0);
    c.density.resize(n, 0.0);
    let max_front = model.params.constants.leader_max_neighbours;
    let mut leader = vec![false; n];
    let mut guide = vec![[0.0; 2]; n];
    for i in 0..nf {
        if p.front_count[i] <= max_front {
            if let Some(g) = model.world.guidance_at(me.pos[i]) {
                leader[i] = true;
                guide[i] = g;
            }
        }
    }
    let mut xi: Vec<f64> = (0..nf).map(|_| rng.sample(StandardNormal)).collect();
    xi.resize(n, 0.0);
    StepDecisions {
        perception: c,
        leader,
        guide,
        xi,
        fixed_speed: Vec::new(),
    }
}

/// The decisions with eq. 6's noise ξ kept (noisy speeds), or set to 0 (the draws still made,
/// so that the random numbers stay in step whatever the setting).
fn quiet(mut dec: StepDecisions, speeds: Speeds) -> StepDecisions {
    if speeds != Speeds::Noisy {
        dec.xi.iter_mut().for_each(|x| *x = 0.0);
    }
    dec
}

/// The simulated animals followed by the scene's (constants): the state of a conditioned step.
fn with_scene(state: &HerdState, scene: &[P2], heads: &[P2]) -> HerdState {
    let device = state.x.device();
    let cat = |a: &Tensor<1>, v: Vec<f64>| Tensor::cat(vec![a.clone(), vec_tensor(v, &device)], 0);
    HerdState {
        x: cat(&state.x, scene.iter().map(|p| p[0]).collect()),
        y: cat(&state.y, scene.iter().map(|p| p[1]).collect()),
        hx: cat(&state.hx, heads.iter().map(|h| h[0]).collect()),
        hy: cat(&state.hy, heads.iter().map(|h| h[1]).collect()),
        speed: cat(&state.speed, vec![0.0; scene.len()]),
    }
}

/// The step's state with every animal moved at its tracked speed into frame `f + 1`,
/// |p(f + 1) − p(f)| / Δt, along the step's new heading (eq. 6's speed where it is not tracked in
/// both frames): p' = p + Δt v' d', the gradient reaching θ through d'.
fn tracked_speeds(
    before: &HerdState,
    next: HerdState,
    t: &TrackSet,
    ids: &[u64],
    f: usize,
    dt: f64,
) -> Result<HerdState> {
    let own = read_vec(&next.speed)?;
    let v: Vec<f64> = ids
        .iter()
        .zip(own)
        .map(|(&id, v)| t.back_vel(f + 1, id).map_or(v, |u| u[0].hypot(u[1])))
        .collect();
    let speed = vec_tensor(v, &before.x.device());
    let step = speed.clone().mul_scalar(dt);
    Ok(HerdState {
        x: before.x.clone() + next.hx.clone() * step.clone(),
        y: before.y.clone() + next.hy.clone() * step,
        hx: next.hx,
        hy: next.hy,
        speed,
    })
}

/// The first `n` rows of a state.
fn first(state: HerdState, n: usize) -> HerdState {
    HerdState {
        x: state.x.narrow(0, 0, n),
        y: state.y.narrow(0, 0, n),
        hx: state.hx.narrow(0, 0, n),
        hy: state.hy.narrow(0, 0, n),
        speed: state.speed.narrow(0, 0, n),
    }
}

/// Rolls out window `w` of `clip` with `forces` on `device`: `each(k, state, leaders)` sees the
/// rolled-out animals after step k (1-based, frame f₀ + k) and which of them led in it (§5.1). Decisions are live (drawn from `rng`, optionally
/// recorded) or replayed from a recording of the same window; `speeds` says where the animals'
/// speeds come from (eq. 6 with or without its noise ξ, or the tracks). Returns the animals' ids,
/// in state order, or `None` when no animal can start.
#[allow(clippy::too_many_arguments)]
pub fn roll<R: Rng>(
    clip: &TrackClip,
    w: &Window,
    rollout: Rollout,
    speeds: Speeds,
    forces: &ForceTensors,
    device: &Device,
    mut decide: Decide<'_, R>,
    mut each: impl FnMut(usize, &HerdState, &[bool]) -> Result<()>,
) -> Result<Option<Vec<u64>>> {
    let rows = clip.starters(w.start);
    if rows.is_empty() {
        return Ok(None);
    }
    let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
    let nf = ids.len();
    let mut model = clip.model.clone();
    model.world.guidance = clip.guidance_for(w.start);
    if let Decide::Replay(rec) = &decide {
        if rec.steps.len() < w.steps || rec.agents != nf {
            return Err(Error::invalid(format!(
                "the recording holds {} steps of {} animals; the window has {} steps of {nf}",
                rec.steps.len(),
                rec.agents,
                w.steps
            )));
        }
    }
    let mut state = HerdState::from_rows(&rows, device);
    let t = &clip.tracks;
    for k in 0..w.steps {
        let f = w.start + k;
        let live;
        let leaders: Vec<bool>;
        let next = match rollout {
            Rollout::Free => {
                let dec = match &mut decide {
                    Decide::Replay(rec) => &rec.steps[k],
                    Decide::Live { rng, record } => {
                        live = quiet(model.decide(&state.snapshot()?, *rng), speeds);
                        if let Some(r) = record {
                            r.steps.push(live.clone());
                        }
                        &live
                    }
                };
                leaders = dec.leader.clone();
                model.step(forces, &state, dec)?
            }
            Rollout::Conditioned => {
                let here = t.at(f);
                let pos: Vec<P2> = here.iter().map(|a| a.pos).collect();
                let heads: Vec<P2> = here.iter().map(|a| t.heading(f, a.id)).collect();
                let dec = match &mut decide {
                    Decide::Replay(rec) => &rec.steps[k],
                    Decide::Live { rng, record } => {
                        let own: Vec<Option<u32>> = ids
                            .iter()
                            .map(|id| {
                                here.binary_search_by_key(id, |a| a.id)
                                    .ok()
                                    .map(|i| i as u32)
                            })
                            .collect();
                        let scene = Scene {
                            pos: &pos,
                            head: &heads,
                        };
                        let dec =
                            conditioned_decisions(&model, &state.snapshot()?, &own, scene, *rng);
                        live = quiet(dec, speeds);
                        if let Some(r) = record {
                            r.steps.push(live.clone());
                        }
                        &live
                    }
                };
                leaders = dec.leader[..nf].to_vec();
                let both = with_scene(&state, &pos, &heads);
                first(model.step(forces, &both, dec)?, nf)
            }
        };
        state = match speeds {
            Speeds::Tracks => tracked_speeds(&state, next, t, &ids, f, model.dt)?,
            _ => next,
        };
        each(k + 1, &state, &leaders)?;
    }
    Ok(Some(ids))
}

/// What a window is scored against after one step: per rolled-out animal, its tracked position
/// and, where it moved faster than `min_speed`, its tracked heading (the direction of its
/// displacement into the frame: the model's d' of eq. 2).
pub struct Targets {
    pub pos: Vec<Option<P2>>,
    pub head: Vec<Option<P2>>,
}

/// The targets of `ids` in frame `f` of `tracks`.
pub fn targets(tracks: &TrackSet, ids: &[u64], f: usize, min_speed: f64) -> Targets {
    let pos = ids.iter().map(|&id| tracks.pos(f, id)).collect();
    let head = ids
        .iter()
        .map(|&id| {
            let v = tracks.back_vel(f, id)?;
            (v[0].hypot(v[1]) > min_speed)
                .then(|| super::data::unit(v))
                .flatten()
        })
        .collect();
    Targets { pos, head }
}

/// The squared errors of a window, as tensors (for the gradient) and counts.
pub struct WindowLoss {
    /// Σ |p − p̂|² + w_h Σ |d − d̂|² per scored sample: Σ_pos / n_pos + w_h Σ_head / n_head.
    pub loss: Tensor<1>,
    pub pos_sq: f64,
    pub n_pos: usize,
    pub head_sq: f64,
    pub n_head: usize,
    /// Σ of the spacing term's squared sorted differences (BL², [`super::spacing`]) and how many
    /// distances it compared (0 when `spacing_weight` is 0).
    pub spacing_sq: f64,
    pub n_spacing: usize,
}

/// Σ over the animals of `m_i · ((a_i − ta_i)² + (b_i − tb_i)²)` for the targets `t` (masked
/// where absent), and how many were present.
fn masked_sq(a: &Tensor<1>, b: &Tensor<1>, t: &[Option<P2>]) -> (Tensor<1>, usize) {
    let device = a.device();
    let m: Vec<f64> = t.iter().map(|v| v.is_some() as u8 as f64).collect();
    let n = m.iter().filter(|&&v| v > 0.0).count();
    let ta = vec_tensor(t.iter().map(|v| v.map_or(0.0, |p| p[0])).collect(), &device);
    let tb = vec_tensor(t.iter().map(|v| v.map_or(0.0, |p| p[1])).collect(), &device);
    let m = vec_tensor(m, &device);
    let e = (a.clone() - ta).square() + (b.clone() - tb).square();
    ((e * m).sum(), n)
}

/// The window's loss (mean squared position error + `heading_weight` × mean squared heading
/// error over the scored samples: each animal at each step while it has followed, not led, since
/// the window's start; + `spacing_weight` × the mean squared difference of the sorted
/// nearest-neighbour distances of the same samples, [`super::spacing`]) after rolling it out as
/// [`roll`] does; `None` when no animal can start or nothing is scored.
pub fn window_loss<R: Rng>(
    clip: &TrackClip,
    w: &Window,
    how: &Scoring,
    forces: &ForceTensors,
    device: &Device,
    decide: Decide<'_, R>,
) -> Result<Option<WindowLoss>> {
    let (heading_weight, min_speed) = (how.heading_weight, how.min_speed);
    let mut pos: Option<Tensor<1>> = None;
    let mut head: Option<Tensor<1>> = None;
    let mut spacing: Option<Tensor<1>> = None;
    let (mut n_pos, mut n_head, mut n_spacing) = (0, 0, 0);
    let ids: Vec<u64> = clip.starters(w.start).iter().map(|r| r.id).collect();
    let add = |acc: &mut Option<Tensor<1>>, t: Tensor<1>| {
        *acc = Some(match acc.take() {
            Some(a) => a + t,
            None => t,
        })
    };
    // Leaders follow the guidance, not θ (§5.1): an animal is scored while it has followed at
    // every step of the window so far, as E_mean scores followers (eq. 7).
    let mut follower = vec![true; ids.len()];
    let rolled = roll(
        clip,
        w,
        how.rollout,
        how.speeds,
        forces,
        device,
        decide,
        |k, s, lead| {
            let mut tg = targets(&clip.tracks, &ids, w.start + k, min_speed);
            for (i, &l) in lead.iter().enumerate() {
                follower[i] &= !l;
                if !follower[i] {
                    tg.pos[i] = None;
                    tg.head[i] = None;
                }
            }
            let (p, np) = masked_sq(&s.x, &s.y, &tg.pos);
            let (h, nh) = masked_sq(&s.hx, &s.hy, &tg.head);
            n_pos += np;
            n_head += nh;
            add(&mut pos, p);
            add(&mut head, h);
            if how.spacing_weight > 0.0 {
                let here = clip.tracks.at(w.start + k);
                let (sp, si): (Vec<P2>, Vec<u64>) = here.iter().map(|a| (a.pos, a.id)).unzip();
                let around = match how.rollout {
                    Rollout::Free => Neighbours::Scored,
                    Rollout::Conditioned => Neighbours::Scene {
                        pos: &sp,
                        ids: &si,
                        own: &ids,
                    },
                };
                if let Some((t, n)) = spacing_sq(&s.x, &s.y, &tg.pos, &around)? {
                    n_spacing += n;
                    add(&mut spacing, t);
                }
            }
            Ok(())
        },
    )?;
    let (Some(_), Some(pos), Some(head)) = (rolled, pos, head) else {
        return Ok(None);
    };
    if n_pos == 0 {
        return Ok(None);
    }
    let pos_sq = read_vec(&pos.clone().detach())?[0];
    let head_sq = read_vec(&head.clone().detach())?[0];
    let mut loss = pos.div_scalar(n_pos as f64);
    if n_head > 0 && heading_weight > 0.0 {
        loss = loss + head.mul_scalar(heading_weight / n_head as f64);
    }
    let mut spacing_total = 0.0;
    if let Some(sp) = spacing.filter(|_| n_spacing > 0) {
        spacing_total = read_vec(&sp.clone().detach())?[0];
        loss = loss + sp.mul_scalar(how.spacing_weight / n_spacing as f64);
    }
    Ok(Some(WindowLoss {
        loss,
        pos_sq,
        n_pos,
        head_sq,
        n_head,
        spacing_sq: spacing_total,
        n_spacing,
    }))
}
