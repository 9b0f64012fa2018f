//! `herdfit simulate`: a parameter set run from an initial herd, written as a trajectory CSV
//! (`frame,time,id,x,y,vx,vy,role`; frame 0 is the initial state), optionally recording or
//! replaying the run's no-gradient decisions (perception, roles, noise).

use crate::backend::{device, Compute, Precision};
use crate::data::agents::{out_of_range, push_traj_frame, read_init_csv, AgentRow, TRAJ_HEADER};
use crate::data::atomic::{check_writable, AtomicFile};
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::sim::{
    random_herd, theta_tensor, Decide, Guidance, HerdSpec, HerdState, Model, Recording, World,
};
use crate::progress::Progress;
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Settings of a simulation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateConfig {
    /// Number of steps (frames after frame 0).
    pub steps: usize,
    /// Frames per second; Δt = 1 / fps.
    pub fps: f64,
    /// Speed noise v_σ (BL/s) of eq. 6, overriding the parameter set's `speed.std`; 0 makes the
    /// run deterministic.
    pub speed_noise: Option<f64>,
    /// Uniform guidance direction for leaders; without it leaders act as followers.
    pub guidance: Option<[f64; 2]>,
    pub precision: Precision,
    /// Where the tensors live (left out of files when `cpu`).
    #[serde(skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
    pub seed: u64,
}

impl Default for SimulateConfig {
    fn default() -> Self {
        SimulateConfig {
            steps: 250,
            fps: 25.0,
            speed_noise: None,
            guidance: None,
            precision: Precision::F32,
            device: Compute::Cpu,
            seed: 0,
        }
    }
}

impl SimulateConfig {
    /// Checks the steps, frame rate, speed noise and guidance; errors name the key.
    pub fn check(&self) -> Result<()> {
        crate::error::check_counts(&[("steps", self.steps)])?;
        crate::limits::check_fps("fps", self.fps)?;
        crate::limits::check_count("steps", self.steps, crate::limits::MAX_STEPS)?;
        if let Some(s) = self.speed_noise {
            if !(s.is_finite() && s >= 0.0) {
                return Err(Error::config("speed_noise", format!("{s} must be ≥ 0")));
            }
            crate::limits::check_magnitude("speed_noise", s, crate::limits::MAX_SPEED)?;
        }
        if let Some([x, y]) = self.guidance {
            if !(x.is_finite() && y.is_finite()) || (x == 0.0 && y == 0.0) {
                return Err(Error::config(
                    "guidance",
                    "the direction must be finite and non-zero",
                ));
            }
        }
        Ok(())
    }
}

/// Where the initial herd of a run comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, rename_all = "lowercase")]
pub enum HerdSource {
    /// An initial-state CSV (`id,x,y,vx,vy`).
    Init(PathBuf),
    /// The built-in random herd of N agents (one per 2 BL², heading +x ± 20°).
    Agents(usize),
}

impl HerdSource {
    /// The herd's rows (`world` places the random herd clear of obstacles).
    pub fn rows(&self, params: &Params, world: &World, seed: u64) -> Result<Vec<AgentRow>> {
        match self {
            HerdSource::Init(p) => read_init_csv(p),
            HerdSource::Agents(n) => {
                random_herd(&HerdSpec::standard(*n), &params.speed, world, seed)
            }
        }
    }
}

/// The files of a run of the model: the parameter set (the built-in set when absent), the
/// initial herd, and the decisions to record or to replay (`simulate` and `gradcheck`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RunFiles {
    pub params: Option<PathBuf>,
    pub herd: Option<HerdSource>,
    pub record: Option<PathBuf>,
    pub replay: Option<PathBuf>,
}

impl RunFiles {
    /// A built-in herd within [`crate::limits::MAX_AGENTS`] (checked before it is drawn).
    pub fn check(&self) -> Result<()> {
        if let Some(HerdSource::Agents(n)) = &self.herd {
            crate::limits::check_count("agents", *n, crate::limits::MAX_AGENTS)?;
        }
        Ok(())
    }
}

/// A simulation with its files: the run's ([`RunFiles`], a herd required) and the trajectory
/// CSV.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimulateJob {
    pub run: RunFiles,
    pub out: PathBuf,
    pub config: SimulateConfig,
}

impl SimulateJob {
    /// Checks the settings and that there is a herd; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.config.check()?;
        self.run.check()?;
        if self.run.herd.is_none() {
            return Err(Error::config(
                "herd",
                "give the initial herd: an INIT.csv file or a number of agents",
            ));
        }
        Ok(())
    }
}

/// Loads a parameter set, or the built-in one.
pub fn load_params(path: Option<&Path>) -> Result<Params> {
    match path {
        Some(p) => Params::load(p),
        None => Ok(Params::default()),
    }
}

/// Runs the simulation and writes the trajectories (and the recording); returns the number of
/// agents.
pub fn simulate(job: &SimulateJob, progress: &mut dyn Progress) -> Result<usize> {
    let cfg = &job.config;
    job.check()?;
    let params = run_params(job.run.params.as_deref(), cfg)?;
    let rows = match &job.run.herd {
        Some(h) => h.rows(&params, &world_of(cfg), cfg.seed)?,
        None => {
            return Err(Error::config(
                "herd",
                "give the initial herd: an INIT.csv file or a number of agents",
            ))
        }
    };
    let replay = job.run.replay.as_deref().map(Recording::load).transpose()?;
    if let (Some(r), Some(p)) = (&replay, &job.run.replay) {
        if r.steps.len() < cfg.steps || r.agents != rows.len() {
            return Err(Error::file(
                p,
                format!(
                    "holds {} steps of {} agents; {} steps of {} requested",
                    r.steps.len(),
                    r.agents,
                    cfg.steps,
                    rows.len()
                ),
            ));
        }
    }
    crate::limits::check_count("agents", rows.len(), crate::limits::MAX_AGENTS)?;
    // A trajectory row is about 100 bytes of text.
    let rows_out = rows.len() as f64 * (cfg.steps as f64 + 1.0);
    crate::limits::check_disk("steps", &job.out, rows_out * 100.0)?;
    check_writable(&job.out)?;
    if let Some(r) = &job.run.record {
        check_writable(r)?;
    }
    let n = rows.len();
    let mut out = AtomicFile::create(&job.out)?;
    let mut text = String::with_capacity(64 * n);
    text.push_str(TRAJ_HEADER);
    text.push('\n');
    let record = job.run.record.is_some();
    let run = Run {
        params,
        rows,
        replay: replay.as_ref(),
        record,
    };
    let rec = run_frames(run, cfg, progress, &mut |frame, time, rows, leader| {
        push_traj_frame(&mut text, frame, time, rows, leader);
        out.write_str(&text)?;
        text.clear();
        Ok(())
    })?;
    if let (Some(path), Some(rec)) = (&job.run.record, &rec) {
        rec.save(path)?;
    }
    out.commit()?;
    Ok(n)
}

/// The parameter set of a run (the built-in one when `path` is absent), with the config's speed
/// noise.
fn run_params(path: Option<&Path>, cfg: &SimulateConfig) -> Result<Params> {
    Ok(with_speed_noise(load_params(path)?, cfg))
}

/// `params` with the config's speed noise, when it sets one.
fn with_speed_noise(mut params: Params, cfg: &SimulateConfig) -> Params {
    if let Some(s) = cfg.speed_noise {
        params.speed.std = s;
    }
    params
}

/// The open world of a simulation: no obstacles, the config's uniform guidance.
fn world_of(cfg: &SimulateConfig) -> World {
    World {
        obstacles: None,
        guidance: cfg.guidance.map_or(Guidance::None, Guidance::Uniform),
        fixed_speed: None,
    }
}

/// What one run starts from: the parameter set (speed noise applied), the initial herd, the
/// decisions to replay, and whether to record them.
struct Run<'a> {
    params: Params,
    rows: Vec<AgentRow>,
    replay: Option<&'a Recording>,
    record: bool,
}

/// Receives each frame of a run: its index, time (s), the agents' rows in the herd's order and
/// their leader flags. An error stops the run.
type FrameSink<'a> = dyn FnMut(usize, f64, &[AgentRow], &[bool]) -> Result<()> + 'a;

/// Runs `cfg.steps` steps of the model from `run.rows`, handing frames 0..=steps to `frame`;
/// returns the recording when asked for. Stops with [`Error::Interrupted`] when `progress` asks.
fn run_frames(
    run: Run<'_>,
    cfg: &SimulateConfig,
    progress: &mut dyn Progress,
    frame: &mut FrameSink<'_>,
) -> Result<Option<Recording>> {
    let device = device(cfg.device, cfg.precision)?;
    let model = Model {
        params: run.params,
        world: world_of(cfg),
        dt: 1.0 / cfg.fps,
        force_kernel: crate::herd::sim::ForceKernel::default(),
    };
    let ids: Vec<u64> = run.rows.iter().map(|r| r.id).collect();
    let theta = theta_tensor(&model.params.to_vec(), &device);
    let state = HerdState::from_rows(&run.rows, &device);
    let mut prev = run.rows;
    let mut rec = run.record.then(|| Recording::new(ids.len()));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x005e_ed0f_5eed);
    progress.start("simulate", cfg.steps as u64);
    let decide = match run.replay {
        Some(r) => Decide::Replay(r),
        None => Decide::Live {
            rng: &mut rng,
            record: rec.as_mut(),
        },
    };
    let end = model.rollout(&theta, state, cfg.steps, decide, |t, dec, next| {
        frame(t, t as f64 * model.dt, &prev, &dec.leader)?;
        prev = next.rows(&ids)?;
        let pts = prev.iter().map(|r| (r.x, r.y));
        crate::limits::check_state(t + 1, pts, "fps, the parameter set's speeds and the herd")?;
        progress.inc(1);
        progress.check()
    })?;
    progress.finish();
    // Roles of the last frame: the decision the next step would take.
    let last_roles = match run.replay {
        Some(r) if r.steps.len() > cfg.steps => r.steps[cfg.steps].leader.clone(),
        _ => {
            let mut rng2 = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
            model.decide(&end.snapshot()?, &mut rng2).leader
        }
    };
    frame(cfg.steps, cfg.steps as f64 * model.dt, &prev, &last_roles)?;
    Ok(rec)
}

/// The initial herd of an in-memory simulation.
#[derive(Clone, Debug, PartialEq)]
pub enum Herd {
    /// The built-in random herd of N agents ([`HerdSource::Agents`]).
    Agents(usize),
    /// These agents (ids unique).
    Rows(Vec<AgentRow>),
}

/// A simulation kept in memory: the agents' ids and, per frame 0..=steps and agent,
/// `[x, y, vx, vy, leader]` (leader 1 or 0).
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    pub ids: Vec<u64>,
    pub frames: ndarray::Array3<f64>,
}

/// [`simulate`] without files: the parameter set `params` (the built-in one when absent) run
/// from `herd`; the same frames as the trajectory CSV of [`simulate`] with the same seed.
pub fn simulate_frames(
    params: Option<Params>,
    herd: Herd,
    cfg: &SimulateConfig,
    progress: &mut dyn Progress,
) -> Result<Trajectory> {
    cfg.check()?;
    let params = match params {
        Some(p) => {
            p.validate()?;
            p
        }
        None => Params::default(),
    };
    let params = with_speed_noise(params, cfg);
    let rows = match herd {
        Herd::Agents(n) => {
            crate::limits::check_count("agents", n, crate::limits::MAX_AGENTS)?;
            HerdSource::Agents(n).rows(&params, &world_of(cfg), cfg.seed)?
        }
        Herd::Rows(rows) => check_rows(rows)?,
    };
    let n = rows.len();
    crate::limits::check_memory(
        "steps",
        "the trajectory",
        (cfg.steps as f64 + 1.0) * n as f64 * 40.0,
    )?;
    let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
    let mut frames = ndarray::Array3::<f64>::zeros((cfg.steps + 1, n, 5));
    let run = Run {
        params,
        rows,
        replay: None,
        record: false,
    };
    run_frames(run, cfg, progress, &mut |f, _, rows, leader| {
        for (a, (r, &l)) in rows.iter().zip(leader).enumerate() {
            let v = [r.x, r.y, r.vx, r.vy, if l { 1.0 } else { 0.0 }];
            for (k, x) in v.into_iter().enumerate() {
                frames[[f, a, k]] = x;
            }
        }
        Ok(())
    })?;
    Ok(Trajectory { ids, frames })
}

/// An initial herd given in memory: not empty, unique ids, finite values within the limits.
fn check_rows(rows: Vec<AgentRow>) -> Result<Vec<AgentRow>> {
    if rows.is_empty() {
        return Err(Error::config("herd", "no agents (empty herd)"));
    }
    crate::limits::check_count("agents", rows.len(), crate::limits::MAX_AGENTS)?;
    let mut seen = std::collections::HashSet::new();
    for r in &rows {
        if !seen.insert(r.id) {
            return Err(Error::config("herd", format!("duplicate id {}", r.id)));
        }
        if let Some(m) = out_of_range(r) {
            return Err(Error::config("herd", format!("agent {}: {m}", r.id)));
        }
    }
    Ok(rows)
}
