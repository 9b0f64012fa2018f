//! The differentiable herd-agent model (paper §5, DESIGN §4).
//!
//! One step k → k+1 is a pipeline of named stages:
//! 1. [`Model::decide`] — perception, roles and OU noise, **no gradient** (kernels crate). The
//!    result, [`StepDecisions`], can be recorded and replayed ([`Recording`]).
//! 2. [`Model::forces`] — the Gaussian-weighted forces of eq. 3–5, by one fused operation with a
//!    hand-written backward ([`fused_forces`]: ndarray, or CubeCL kernels with the feature `gpu`)
//!    or as tensor ops over the padded neighbour lists ([`Model::reference_forces`]); either way
//!    gradients flow to the 12 parameters.
//! 3. [`Model::step`] — the direction update of eq. 2, the OU speed of eq. 6 and the position
//!    update.
//!
//! [`Model::rollout`] unrolls T steps; on an autodiff device the final state carries the gradient
//! of the whole unrolled run.

mod fused;
#[cfg(feature = "gpu")]
mod fused_cube;
mod herd;
mod op_inputs;
mod reference;
mod rollout;
mod snapshot;
mod world;

pub use fused::{fused_forces, fused_op_passes, plain_step, ForceKernel, ForceOp};
#[cfg(feature = "gpu")]
pub use fused_cube::cube_op_passes;
pub use herd::{random_herd, HerdSpec};
pub use rollout::{Decide, Guided, StepHooks};
pub use snapshot::Snapshot;
pub use world::{obstacle_map, Guidance, SpeedMap, World};

use crate::data::agents::AgentRow;
use crate::data::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::herd::params::{Constants, Params, N_PARAMS};
use burn::tensor::{Device, Tensor, TensorData};
use herdfit_kernels::{perceive, Capsule, NeighbourLists, Perception, PerceptionConfig, P2};
use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Skin s (BL) of the neighbour candidates a run keeps between steps ([`NeighbourLists`]):
/// candidates within R_perc + s, rebuilt once an agent has moved s/2. It changes no decision,
/// only the time; chosen by the criterion sweep `cargo bench --bench step -- neighbour_skin`
/// (docs/performance.md).
pub const NEIGHBOUR_SKIN: f64 = 0.5;

/// Guard of the vector normalisation N(·) of eq. 2 (BL²/s²).
const NORM_EPS: f64 = 1e-12;

/// Speed (BL/s) below which eq. 2's u = v·d + Δt F may vanish: √[`NORM_EPS`].
const REST_SPEED: f64 = 1e-6;

/// Whether eq. 2 leaves an agent's heading as it was: speed `v` below [`REST_SPEED`] and
/// |u|² = `ux`² + `uy`² below [`NORM_EPS`], where N(u) is no direction.
fn at_rest(v: f64, ux: f64, uy: f64) -> bool {
    v < REST_SPEED && ux * ux + uy * uy < NORM_EPS
}

/// Batched herd state: one entry per agent, all on one device.
#[derive(Clone, Debug)]
pub struct HerdState {
    /// Positions (BL).
    pub x: Tensor<1>,
    pub y: Tensor<1>,
    /// Unit headings.
    pub hx: Tensor<1>,
    pub hy: Tensor<1>,
    /// Speeds (BL/s). They carry no gradient: eq. 6 depends on θ only through the local
    /// density, a piecewise-constant neighbour count.
    pub speed: Tensor<1>,
}

fn vec_tensor(v: Vec<f64>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn mat_tensor(v: Vec<f64>, rows: usize, cols: usize, device: &Device) -> Tensor<2> {
    Tensor::from_data(TensorData::new(v, [rows, cols]), device)
}

/// Reads a rank-1 tensor back as f64 values.
pub fn read_vec(t: &Tensor<1>) -> Result<Vec<f64>> {
    if let Some(v) = fused::read_ndarray(t) {
        return Ok(v);
    }
    t.clone()
        .try_into_vec_as::<f64>()
        .map_err(|e| Error::Internal(format!("tensor read-back failed: {e:?}")))
}

impl HerdState {
    /// The same state with positions and headings tracked by autodiff (speeds carry no gradient,
    /// eq. 6), for gradients with respect to the initial state.
    pub fn require_grad(self) -> Self {
        HerdState {
            x: self.x.require_grad(),
            y: self.y.require_grad(),
            hx: self.hx.require_grad(),
            hy: self.hy.require_grad(),
            speed: self.speed,
        }
    }

    /// Builds a state from agent rows: velocity gives heading and speed (a standing agent faces +x).
    pub fn from_rows(rows: &[AgentRow], device: &Device) -> Self {
        Self::from_snapshot(&Snapshot::of_rows(rows), device)
    }

    /// Puts a plain state on the device.
    pub fn from_snapshot(s: &Snapshot, device: &Device) -> Self {
        HerdState {
            x: vec_tensor(s.pos.iter().map(|p| p[0]).collect(), device),
            y: vec_tensor(s.pos.iter().map(|p| p[1]).collect(), device),
            hx: vec_tensor(s.head.iter().map(|h| h[0]).collect(), device),
            hy: vec_tensor(s.head.iter().map(|h| h[1]).collect(), device),
            speed: vec_tensor(s.speed.clone(), device),
        }
    }

    /// Number of agents.
    pub fn n(&self) -> usize {
        self.x.dims()[0]
    }

    /// Reads the state back from the device.
    pub fn snapshot(&self) -> Result<Snapshot> {
        let (x, y) = (read_vec(&self.x)?, read_vec(&self.y)?);
        let (hx, hy) = (read_vec(&self.hx)?, read_vec(&self.hy)?);
        Ok(Snapshot {
            pos: x.into_iter().zip(y).map(|(a, b)| [a, b]).collect(),
            head: hx.into_iter().zip(hy).map(|(a, b)| [a, b]).collect(),
            speed: read_vec(&self.speed)?,
        })
    }

    /// Agent rows (velocity = speed · heading) with the given ids.
    pub fn rows(&self, ids: &[u64]) -> Result<Vec<AgentRow>> {
        Ok(self.snapshot()?.rows(ids))
    }

    /// The same values cut from the autodiff graph (used between training windows).
    pub fn detach(self) -> Self {
        HerdState {
            x: self.x.detach(),
            y: self.y.detach(),
            hx: self.hx.detach(),
            hy: self.hy.detach(),
            speed: self.speed.detach(),
        }
    }
}

/// Everything decided without gradient in one step: perception (neighbour and obstacle lists,
/// front-cone counts, local density), roles, leader directions and the OU noise ξ.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepDecisions {
    pub perception: Perception,
    /// Effective leaders: few visible neighbours ahead **and** guidance at their cell (§5.1).
    pub leader: Vec<bool>,
    /// The guidance direction a leader takes (zero for followers).
    pub guide: Vec<P2>,
    /// Standard-normal draws of eq. 6.
    pub xi: Vec<f64>,
    /// Per agent, the fixed v_μ of eq. 6 of the zone it stands in ([`World::fixed_speed`]);
    /// empty when the world fixes no speed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub fixed_speed: Vec<Option<f64>>,
}

/// Schema tag of recording files.
pub const RECORDING_SCHEMA: &str = "herdfit.recording/1";

/// The decisions of a whole run, for exact replay.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Recording {
    pub schema: String,
    pub agents: usize,
    pub steps: Vec<StepDecisions>,
}

impl Recording {
    /// An empty recording for `agents` agents.
    pub fn new(agents: usize) -> Self {
        Recording {
            schema: RECORDING_SCHEMA.into(),
            agents,
            steps: Vec::new(),
        }
    }

    /// Writes the recording as JSON (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string(self)
            .map_err(|e| Error::Internal(format!("serialising recording: {e}")))?;
        write_atomic(path, text.as_bytes())
    }

    /// Reads a recording and checks its shape.
    pub fn load(path: &Path) -> Result<Self> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let r: Recording = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a {RECORDING_SCHEMA} file: {e}")))?;
        if r.schema != RECORDING_SCHEMA {
            return Err(Error::file(path, format!("schema is '{}'", r.schema)));
        }
        for (t, s) in r.steps.iter().enumerate() {
            let p = &s.perception;
            let ok = p.n == r.agents
                && p.k >= 1
                && p.ko >= 1
                && p.neighbours.len() == p.n * p.k
                && p.neighbour_mask.len() == p.n * p.k
                && p.neighbour_branch.len() == p.n * p.k
                && p.obstacle_branch.len() == p.n * p.ko
                && p.obstacle_points.len() == p.n * p.ko
                && p.obstacle_mask.len() == p.n * p.ko
                && p.neighbours.iter().all(|&j| (j as usize) < p.n)
                && s.leader.len() == p.n
                && s.guide.len() == p.n
                && s.xi.len() == p.n
                && p.density.len() == p.n
                && p.front_count.len() == p.n;
            if !ok {
                return Err(Error::file(
                    path,
                    format!("step {t}: lists do not match {} agents", r.agents),
                ));
            }
        }
        Ok(r)
    }
}

/// The 12 parameters turned into the per-force tensors of eq. 3–4 (each `[1, 1]`):
/// `w = Ω·W_F`, `α = −½ / R_F²`, `γ = −½ / Φ_F²`, so that `Ω·W_F·WR·WA = w·exp(α d² + γ φ²)`.
#[derive(Clone, Debug)]
pub struct ForceTensors {
    pub w: [Tensor<2>; 4],
    pub alpha: [Tensor<2>; 4],
    pub gamma: [Tensor<2>; 4],
    /// `[n, 1]` tensors: one parameter set per agent (authoring with behaviour regions).
    pub per_agent: bool,
    /// The same values packed for the fused op: `[1, 12]` (or `[n, 12]` per agent) as
    /// `[w_C, w_V, w_A, w_O, α_C, …, α_O, γ_C, …, γ_O]` ([`herdfit_kernels::Coefficients`]).
    pub coef: Tensor<2>,
}

impl ForceTensors {
    /// From the `[12]` parameter tensor `theta` (normalised values, [`crate::herd::params::param_names`]
    /// order). Gradients flow from the forces back to `theta`.
    pub fn new(theta: &Tensor<1>, c: &Constants) -> Self {
        assert_eq!(theta.dims()[0], N_PARAMS, "theta must hold 12 values");
        let at = |i: usize| theta.clone().narrow(0, i, 1).reshape([1, 1]);
        let r2 = c.perception_radius * c.perception_radius;
        let pi2 = std::f64::consts::PI * std::f64::consts::PI;
        let w = std::array::from_fn(|g| at(3 * g).mul_scalar(c.sensitivity));
        // −½ / (θ_i · scale)², the exponent's coefficient of a range parameter (eq. 4).
        let inv =
            |i: usize, scale2: f64| at(i).square().mul_scalar(scale2).recip().mul_scalar(-0.5);
        let alpha = std::array::from_fn(|g| inv(3 * g + 1, r2));
        let gamma = std::array::from_fn(|g| inv(3 * g + 2, pi2));
        let coef = Tensor::cat(
            w.iter()
                .chain(&alpha)
                .chain(&gamma)
                .cloned()
                .collect::<Vec<_>>(),
            1,
        );
        ForceTensors {
            w,
            alpha,
            gamma,
            per_agent: false,
            coef,
        }
    }

    /// One parameter set per zone, differentiable: `theta` holds Z sets of 12 values (`[12·Z]`)
    /// and agent i uses set `zone[i]`; the `[n, 1]` per-agent tensors and the `[n, 12]` packed
    /// coefficients are rows selected from the zones' (eq. 3–4), so gradients reach every zone's
    /// parameters from the agents that used them.
    pub fn zoned(theta: &Tensor<1>, zone: &[usize], c: &Constants) -> Self {
        let z = theta.dims()[0] / N_PARAMS;
        let sets: Vec<ForceTensors> = (0..z)
            .map(|k| ForceTensors::new(&theta.clone().narrow(0, k * N_PARAMS, N_PARAMS), c))
            .collect();
        let device = theta.device();
        let idx: Vec<i64> = zone.iter().map(|&k| k.min(z - 1) as i64).collect();
        let idx =
            Tensor::<1, burn::tensor::Int>::from_data(TensorData::new(idx, [zone.len()]), &device);
        let rows = |pick: &dyn Fn(&ForceTensors) -> Tensor<2>| {
            Tensor::cat(sets.iter().map(pick).collect::<Vec<_>>(), 0).select(0, idx.clone())
        };
        ForceTensors {
            w: std::array::from_fn(|g| rows(&|f| f.w[g].clone())),
            alpha: std::array::from_fn(|g| rows(&|f| f.alpha[g].clone())),
            gamma: std::array::from_fn(|g| rows(&|f| f.gamma[g].clone())),
            per_agent: true,
            coef: rows(&|f| f.coef.clone()),
        }
    }

    /// One parameter set per agent (no gradient): `thetas[i]` are agent i's 12 values.
    pub fn per_agent(thetas: &[[f64; N_PARAMS]], c: &Constants, device: &Device) -> Self {
        let n = thetas.len();
        let col = |f: &dyn Fn(&[f64; N_PARAMS]) -> f64| {
            mat_tensor(thetas.iter().map(f).collect(), n, 1, device)
        };
        let (r, pi) = (c.perception_radius, std::f64::consts::PI);
        let w = std::array::from_fn(|g| col(&|t| t[3 * g] * c.sensitivity));
        let alpha = std::array::from_fn(|g| col(&|t| -0.5 / (t[3 * g + 1] * r).powi(2)));
        let gamma = std::array::from_fn(|g| col(&|t| -0.5 / (t[3 * g + 2] * pi).powi(2)));
        let coef = thetas
            .iter()
            .flat_map(|t| {
                let w = (0..4).map(|g| t[3 * g] * c.sensitivity);
                let a = (0..4).map(|g| -0.5 / (t[3 * g + 1] * r).powi(2));
                let y = (0..4).map(|g| -0.5 / (t[3 * g + 2] * pi).powi(2));
                w.chain(a).chain(y).collect::<Vec<_>>()
            })
            .collect();
        ForceTensors {
            w,
            alpha,
            gamma,
            per_agent: true,
            coef: mat_tensor(coef, n, herdfit_kernels::N_COEF, device),
        }
    }
}

/// Several parameter vectors, one after another (`[12·Z]`, [`ForceTensors::zoned`]), as a tensor
/// on `device`.
pub fn thetas_tensor(thetas: &[f64], device: &Device) -> Tensor<1> {
    vec_tensor(thetas.to_vec(), device)
}

/// A parameter vector as a tensor on `device`.
pub fn theta_tensor(theta: &[f64; N_PARAMS], device: &Device) -> Tensor<1> {
    vec_tensor(theta.to_vec(), device)
}

/// The herd model of one run: parameters, surroundings, time step.
#[derive(Clone, Debug)]
pub struct Model {
    pub params: Params,
    pub world: World,
    /// Time step Δt (s) = 1 / fps.
    pub dt: f64,
    /// Fused force op (default) or the tensor-op reference ([`Model::forces`]).
    pub force_kernel: ForceKernel,
}

impl Model {
    /// Settings of the perception kernel from the constants.
    pub fn perception_config(&self) -> PerceptionConfig {
        let c = &self.params.constants;
        PerceptionConfig {
            radius: c.perception_radius,
            capsule: Capsule {
                half_length: c.capsule_half_length,
                radius: c.capsule_radius,
            },
            occlusion: c.occlusion,
            max_neighbours: c.max_neighbours,
            max_obstacles: c.max_obstacles,
            front_cone: c.leader_cone_deg.to_radians(),
        }
    }

    /// Stage 1, no gradient: perception (DESIGN §4.1), roles (§5.1, DESIGN §4.2) and ξ of eq. 6.
    pub fn decide(&self, snap: &Snapshot, rng: &mut impl Rng) -> StepDecisions {
        let perception = perceive(
            &snap.pos,
            &snap.head,
            self.world.obstacles.as_ref(),
            &self.perception_config(),
        );
        self.decide_from(perception, snap, rng)
    }

    /// [`Model::decide`] with the neighbour candidates kept in `lists` between the steps of a
    /// run: the same decisions, faster.
    pub fn decide_with(
        &self,
        snap: &Snapshot,
        rng: &mut impl Rng,
        lists: &mut NeighbourLists,
    ) -> StepDecisions {
        let perception = lists.perceive(
            &snap.pos,
            &snap.head,
            self.world.obstacles.as_ref(),
            &self.perception_config(),
        );
        self.decide_from(perception, snap, rng)
    }

    /// Roles (§5.1, DESIGN §4.2) and ξ of eq. 6 from this step's perception.
    fn decide_from(
        &self,
        perception: Perception,
        snap: &Snapshot,
        rng: &mut impl Rng,
    ) -> StepDecisions {
        let max_front = self.params.constants.leader_max_neighbours;
        let n = snap.pos.len();
        let mut leader = vec![false; n];
        let mut guide = vec![[0.0; 2]; n];
        for i in 0..n {
            if perception.front_count[i] <= max_front {
                if let Some(g) = self.world.guidance_at(snap.pos[i]) {
                    leader[i] = true;
                    guide[i] = g;
                }
            }
        }
        let xi = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let fixed_speed = match &self.world.fixed_speed {
            Some(m) => snap.pos.iter().map(|&p| m.at(p)).collect(),
            None => Vec::new(),
        };
        StepDecisions {
            perception,
            leader,
            guide,
            xi,
            fixed_speed,
        }
    }

    /// Stage 2: the total force F_i of eq. 3 with the components of eq. 5 and the Gaussian
    /// weights of eq. 4, as `[n, 1]` tensors (x and y).
    ///
    /// FC = Σ WR·WA·(p_j − p_i), FV = −Σ WR·WA·(p_j − p_i), FA = Σ WR·WA·d_j,
    /// FO = −Σ_o WR·WA·(q_o − p_i); F = Ω (W_C FC + W_V FV + W_A FA + W_O FO).
    ///
    /// With [`ForceKernel::Fused`] on the ndarray backend (or burn's Cube backend, feature `gpu`)
    /// this is one operation with a hand-written backward ([`fused_forces`]); otherwise the tensor
    /// ops of [`Model::reference_forces`].
    pub fn forces(
        &self,
        f: &ForceTensors,
        s: &HerdState,
        dec: &StepDecisions,
    ) -> (Tensor<2>, Tensor<2>) {
        if self.force_kernel == ForceKernel::Fused {
            if let Some(out) = fused_forces(f, s, dec) {
                return out;
            }
        }
        Self::reference_forces(f, s, dec)
    }

    /// New speeds by the OU process of eq. 6, v' = v − θ(v − v_μ(ρ_i))Δt + v_σ√Δt ξ, with v_μ(ρ)
    /// from the speed–density table (§6.2), or the agent's zone's fixed speed where the decisions
    /// record one (§7.2.4), clamped to [0, v_max]. Plain values: no gradient.
    pub fn next_speeds(&self, speed: &[f64], dec: &StepDecisions) -> Vec<f64> {
        let sm = &self.params.speed;
        let dt = self.dt;
        speed
            .iter()
            .zip(&dec.perception.density)
            .zip(&dec.xi)
            .enumerate()
            .map(|(i, ((&v, &rho), &xi))| {
                let (mean, cap) = match dec.fixed_speed.get(i) {
                    Some(&Some(m)) => (m, sm.cap_with_fixed(m)),
                    _ => (sm.mean_at(rho), sm.max),
                };
                let v1 = v - sm.reversion * (v - mean) * dt + sm.std * dt.sqrt() * xi;
                v1.clamp(0.0, cap)
            })
            .collect()
    }

    /// Stage 3: one step of the model. Followers turn by eq. 2, d' = N(v·d + Δt F); leaders take
    /// their guidance direction; speeds follow eq. 6; positions p' = p + Δt v' d'.
    pub fn step(&self, f: &ForceTensors, s: &HerdState, dec: &StepDecisions) -> Result<HerdState> {
        self.step_with(f, s, dec, None)
    }

    /// [`Model::step`] with an extra per-agent force added to F of eq. 3 (the hook of §7.5, e.g.
    /// predator avoidance); no gradient flows through it. With the fused kernel on a plain
    /// ndarray device (simulation, no autodiff) the whole step runs on plain values with the same
    /// bytes as these tensor ops (`fused::plain_step`).
    pub fn step_with(
        &self,
        f: &ForceTensors,
        s: &HerdState,
        dec: &StepDecisions,
        extra: Option<&[P2]>,
    ) -> Result<HerdState> {
        let n = s.n();
        if dec.perception.n != n {
            return Err(Error::invalid(format!(
                "decisions are for {} agents, the herd has {n}",
                dec.perception.n
            )));
        }
        if self.force_kernel.is_fused() {
            if let Some(next) = fused::plain_step(self, f, s, dec, extra) {
                return Ok(next);
            }
        }
        let device = s.x.device();
        let (mut fx, mut fy) = self.forces(f, s, dec);
        if let Some(e) = extra {
            fx = fx + mat_tensor(e.iter().map(|v| v[0]).collect(), n, 1, &device);
            fy = fy + mat_tensor(e.iter().map(|v| v[1]).collect(), n, 1, &device);
        }
        let v = s.speed.clone().reshape([n, 1]);
        let ux = v.clone() * s.hx.clone().reshape([n, 1]) + fx.mul_scalar(self.dt);
        let uy = v * s.hy.clone().reshape([n, 1]) + fy.mul_scalar(self.dt);
        let norm = (ux.clone().square() + uy.clone().square())
            .add_scalar(NORM_EPS)
            .sqrt();
        let mut hx = ux.clone() / norm.clone();
        let mut hy = uy.clone() / norm;
        // Eq. 2 leaves d' undefined where u = v·d + Δt F vanishes (an animal at rest with no
        // force, or a vanishing one, on it: a standing pedestrian): below |u|² = ε it keeps d.
        // Checked only where some speed is below √ε.
        let speeds = read_vec(&s.speed)?;
        if speeds.iter().any(|&v| v < REST_SPEED) {
            let (u, w) = (read_vec(&ux.reshape([n]))?, read_vec(&uy.reshape([n]))?);
            let keep: Vec<f64> = (0..n)
                .map(|i| at_rest(speeds[i], u[i], w[i]) as u8 as f64)
                .collect();
            if keep.contains(&1.0) {
                let m = mat_tensor(keep, n, 1, &device);
                let free = m.clone().neg().add_scalar(1.0);
                hx = hx * free.clone() + s.hx.clone().reshape([n, 1]) * m.clone();
                hy = hy * free + s.hy.clone().reshape([n, 1]) * m;
            }
        }
        if dec.leader.iter().any(|&l| l) {
            let follow: Vec<f64> = dec
                .leader
                .iter()
                .map(|&l| if l { 0.0 } else { 1.0 })
                .collect();
            let follow = mat_tensor(follow, n, 1, &device);
            let gx = mat_tensor(dec.guide.iter().map(|g| g[0]).collect(), n, 1, &device);
            let gy = mat_tensor(dec.guide.iter().map(|g| g[1]).collect(), n, 1, &device);
            hx = hx * follow.clone() + gx;
            hy = hy * follow + gy;
        }
        let speed = self.next_speeds(&speeds, dec);
        let speed = vec_tensor(speed, &device);
        let hx = hx.reshape([n]);
        let hy = hy.reshape([n]);
        let step_x = hx.clone() * speed.clone().mul_scalar(self.dt);
        let step_y = hy.clone() * speed.clone().mul_scalar(self.dt);
        Ok(HerdState {
            x: s.x.clone() + step_x,
            y: s.y.clone() + step_y,
            hx,
            hy,
            speed,
        })
    }
}
