//! The fit loop (paper §6.1): epochs × clips × windows of planned, then evaluated, steps; the
//! gradient of each window's loss, the optimiser step, population control between windows.

use super::anchor::Anchors;
use super::checkpoint::{resume, save_checkpoint, CheckpointDir, Learnt, ZoneStarts};
use super::config::{FitConfig, LossKind, AUTO_UNRESOLVED};
use super::herds::{check_finite_step, grad_of, Forward, Herds};
use super::log::LogRow;
use super::loss::StepTarget;
use super::loss::{add, density_loss, ensemble_loss_weighted, fields_loss_weighted, step_loss};
use super::plan::{plan_step, window_loss};
use super::target::Stencil;
use crate::backend::device;
use crate::data::agents::AgentRow;
use crate::data::boundary::Gates;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::eval::clip_model;
use crate::herd::guidance::guidance_fields;
use crate::herd::params::SpeedModel;
use crate::herd::params::ALIGNMENT;
use crate::herd::params::{Params, N_PARAMS};
use crate::herd::sim::{read_vec, Model};
use crate::herd::sim::{thetas_tensor, ForceTensors, Guidance, HerdState};
use crate::herd::start::start_herd;
use crate::herd::zones::Zones;
use crate::optim::OptState;
use crate::progress::Proceed;
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
pub use zone::{fit_zones, zone_loss_of, ZoneFitResult};

mod zone;

/// Result of a fit.
#[derive(Clone, Debug)]
pub struct FitResult {
    pub params: Params,
    pub start: [f64; N_PARAMS],
    pub log: Vec<LogRow>,
}

fn epoch_rng(seed: u64, epoch: usize) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ (epoch as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Runs the fit. `progress(epoch, frame, e_mean, ms_per_step)` is called after every window.
pub fn fit<R: Proceed>(
    clip: &ClipFields,
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<FitResult> {
    fit_inner(&[clip], init, cfg, ckpt, true, progress)
}

/// [`fit`] to several clips of one kind of herd at once (paper §7.6): every epoch walks through
/// the clips in turn, each with its own herds, obstacles, frame rate and speed model, and one set
/// of 12 parameters learns from all of them. `cfg.frames` applies to every clip. The exported
/// speed model is the first clip's.
pub fn fit_clips<R: Proceed>(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<FitResult> {
    fit_inner(clips, init, cfg, ckpt, true, progress)
}

/// The loss of a parameter set on a clip without learning: one epoch of the fit's schedule
/// (epoch-0 herd and noise) with no updates; returns the mean E_mean, E_var and field-matching
/// loss over its windows. Comparing two parameter sets this way uses the same herd, noise and
/// population control seed.
pub fn loss_of(clips: &[&ClipFields], params: &Params, cfg: &FitConfig) -> Result<(f64, f64, f64)> {
    let one = FitConfig {
        epochs: 1,
        ..cfg.clone()
    };
    let r = fit_inner(clips, params, &one, None, false, |_, _, _, _| {})?;
    Ok(mean_losses(&r.log))
}

/// The mean E_mean, E_var and field-matching loss over a log's windows.
fn mean_losses(log: &[LogRow]) -> (f64, f64, f64) {
    let n = log.len().max(1) as f64;
    (
        log.iter().map(|x| x.e_mean).sum::<f64>() / n,
        log.iter().map(|x| x.e_var).sum::<f64>() / n,
        log.iter().map(|x| x.e_fields).sum::<f64>() / n,
    )
}

/// Each window's (back-propagated loss, gradient as the fit uses it) over one epoch of the fit's
/// schedule at `params`, without updates: the probe of [`crate::herd::fit::identify()`]. The same
/// `cfg.seed` gives the same herds and noise (common random numbers).
pub fn window_gradients(
    clips: &[&ClipFields],
    params: &Params,
    cfg: &FitConfig,
) -> Result<Vec<(f64, [f64; N_PARAMS])>> {
    let one = FitConfig {
        epochs: 1,
        ..cfg.clone()
    };
    let mut run = FitRun::new(clips, params, &one, false)?;
    run.probe = true;
    let mut learnt = Learnt {
        theta: params.to_vec(),
        opt: OptState::new(N_PARAMS),
        log: Vec::new(),
        probes: Vec::new(),
        zones: Vec::new(),
    };
    let mut rng = epoch_rng(one.seed, 0);
    for ci in 0..clips.len() {
        run.epoch_on_clip(0, ci, &mut learnt, &mut rng, &mut |_, _, _, _| {})?;
    }
    Ok(learnt.probes)
}

/// What one fit shares across its stages: the clips, the settings, the devices, the parameter
/// set whose speed model is exported, and each clip's guidance and stencil.
struct FitRun<'a> {
    clips: &'a [&'a ClipFields],
    init: &'a Params,
    cfg: &'a FitConfig,
    device: Device,
    /// The autodiff device (with burn's gradient checkpointing when asked for).
    ad: Device,
    params: Params,
    per_clip: Vec<(Vec<Guidance>, Stencil)>,
    /// false: evaluate the schedule without updates ([`loss_of`]).
    learn: bool,
    /// Record every window's loss and gradient ([`window_gradients`]).
    probe: bool,
    /// A zone fit's zones: each agent uses its cell's zone's parameter set ([`fit_zones`]).
    zones: Option<&'a Zones>,
    /// Each clip's tracked animals, which start every window when given (`cfg.tracks`).
    anchors: Vec<Option<Anchors>>,
    /// Each clip's open boundary (`cfg.boundary`; closed gates change nothing).
    gates: Vec<Gates>,
}

fn fit_inner<R: Proceed>(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    learn: bool,
    mut progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<FitResult> {
    let run = FitRun::new(clips, init, cfg, learn)?;
    let start = init.to_vec();
    let (mut learnt, first_epoch) = resume(ckpt, cfg, start, &ZoneStarts::default())?;
    for epoch in first_epoch..cfg.epochs {
        let mut rng = epoch_rng(cfg.seed, epoch);
        for ci in 0..clips.len() {
            run.epoch_on_clip(epoch, ci, &mut learnt, &mut rng, &mut progress)?;
        }
        if let Some(c) = ckpt {
            save_checkpoint(c, epoch + 1, &learnt, cfg, start, &ZoneStarts::default())?;
        }
    }
    let mut out = run.params.with_vec(&learnt.theta);
    out.speed = run.params.speed.clone();
    Ok(FitResult {
        params: out,
        start,
        log: learnt.log,
    })
}

impl<'a> FitRun<'a> {
    fn new(
        clips: &'a [&'a ClipFields],
        init: &'a Params,
        cfg: &'a FitConfig,
        learn: bool,
    ) -> Result<Self> {
        if clips.is_empty() {
            return Err(Error::invalid("no clip to fit"));
        }
        if cfg.loss == LossKind::Auto {
            return Err(Error::config("loss", AUTO_UNRESOLVED));
        }
        for clip in clips {
            cfg.check_clip(clip)?;
        }
        init.validate()?;
        let device = device(cfg.device, cfg.precision)?;
        // Long windows can trade time for memory with burn's balanced gradient checkpointing.
        let ad: Device = if cfg.checkpointing {
            device.clone().autodiff().gradient_checkpointing()
        } else {
            device.clone().autodiff()
        };
        let mut params = init.clone();
        // Stage 2 (§6.2) first: the forces are learnt with each clip's own speeds; the exported
        // speed model is the first clip's.
        params.speed = SpeedModel::of_clip(clips[0], &init.speed);
        let per_clip = clips
            .iter()
            .map(|clip| {
                // A still shows no direction to follow: no leaders (§7.2.4).
                let guidance = match cfg.still {
                    Some(_) => vec![Guidance::None; clip.frames()],
                    None => guidance_fields(clip, cfg.guidance_scale),
                };
                (guidance, Stencil::new(clip))
            })
            .collect();
        let anchors = super::anchor::load_all(cfg, clips)?;
        let gates = clips
            .iter()
            .map(|c| cfg.boundary.gates(c))
            .collect::<Result<Vec<_>>>()?;
        Ok(FitRun {
            clips,
            init,
            cfg,
            device,
            ad,
            params,
            per_clip,
            learn,
            probe: false,
            zones: None,
            anchors,
            gates,
        })
    }

    /// One epoch's pass over clip `ci`: fresh herds from the first frame's fields, then window
    /// after window: forward, gradient, optimiser step, population control, log row.
    fn epoch_on_clip<R: Proceed>(
        &self,
        epoch: usize,
        ci: usize,
        learnt: &mut Learnt,
        rng: &mut ChaCha8Rng,
        progress: &mut impl FnMut(usize, usize, f64, f64) -> R,
    ) -> Result<()> {
        let (clip, cfg) = (self.clips[ci], self.cfg);
        let (a, b) = (cfg.frames.start, cfg.frames.end);
        let mut speed_params = self.params.clone();
        speed_params.speed = SpeedModel::of_clip(clip, &self.init.speed);
        let mut model = clip_model(speed_params.with_vec(&learnt.theta), clip);
        model.force_kernel = cfg.force_kernel;
        if let Some(z) = self.zones {
            model.world.fixed_speed = z.speed_map(&clip.grid());
        }
        let mut herds = self.start_herds(&model, clip, a, rng)?;
        let mut f = a;
        while f + 1 < b {
            let w = cfg.window.min(b - 1 - f);
            let t0 = std::time::Instant::now();
            if let Some(rows) = self.anchors[ci].as_ref().and_then(|a| a.at(f)) {
                herds.start_from(rows);
            }
            herds.refill_empty(clip, f, &model, rng);
            if herds.rows.iter().all(|h| h.is_empty()) {
                f += w;
                continue;
            }
            let flat = learnt.flat();
            let (loss, th, fwd) = self.forward(&mut model, ci, &herds, f, w, &flat, rng)?;
            let (em, ev, ef) = (fwd.e_mean, fwd.e_var, fwd.e_fields);
            // A still's settling steps (§7.2.4) are simulated, not learnt from nor logged.
            if cfg.still.is_some_and(|s| f + w <= s.settle) {
                f += w;
                herds.control(clip, &self.gates[ci], f, &fwd, cfg, &model, rng)?;
                progress(epoch, f, em, t0.elapsed().as_secs_f64() * 1e3 / w as f64).proceed()?;
                continue;
            }
            // The gradient is needed to learn and, for the identifiability probe, to record.
            let g = match self.learn || self.probe {
                true => {
                    let value = match self.probe {
                        true => read_vec(&loss.clone().detach())?[0],
                        false => 0.0,
                    };
                    let g = self.gradient(&model, &herds, loss, &th, &fwd, &flat)?;
                    check_finite_step(epoch, ci, f..f + w, [em, ev, ef], &g)?;
                    if self.probe {
                        let mut g0 = [0.0; N_PARAMS];
                        g0.copy_from_slice(&g[..N_PARAMS]);
                        learnt.probes.push((value, g0));
                    }
                    Some(g)
                }
                false => None,
            };
            if let (true, Some(g)) = (self.learn, g) {
                // Learning rate decays linearly to 10 % over the epochs.
                let lr = cfg.lr * (1.0 - 0.9 * epoch as f64 / cfg.epochs.max(1) as f64);
                learnt.update(&g, cfg, lr, rng);
            }
            model.params = model.params.with_vec(&learnt.theta);
            f += w;
            let (de, ve, agents) =
                herds.control(clip, &self.gates[ci], f, &fwd, cfg, &model, rng)?;
            learnt.log.push(LogRow {
                epoch,
                frame: f,
                e_mean: em,
                e_var: ev,
                e_fields: ef,
                density_error: de,
                velocity_error: ve,
                agents: agents / fwd.live.len(),
                theta: learnt.theta,
                clip: ci,
            });
            progress(epoch, f, em, t0.elapsed().as_secs_f64() * 1e3 / w as f64).proceed()?;
        }
        Ok(())
    }

    /// K independent herds (replicas) from the fields of frame `a`, side by side.
    fn start_herds(
        &self,
        model: &Model,
        clip: &ClipFields,
        a: usize,
        rng: &mut ChaCha8Rng,
    ) -> Result<Herds> {
        let replicas = self.cfg.replicas.max(1);
        let mut rows: Vec<Vec<AgentRow>> = Vec::with_capacity(replicas);
        for _ in 0..replicas {
            rows.push(start_herd(
                model,
                clip,
                a,
                &self.cfg.settle,
                rng,
                &self.device,
            )?);
        }
        let next_ids = rows.iter().map(|h| h.len() as u64).collect();
        Ok(Herds { rows, next_ids })
    }

    /// Plans and evaluates the `w` steps of a window from frame `f` for every live replica, and
    /// sums the window's loss: E_mean/E_var weighted by the objective, plus the field-matching or
    /// ensemble term. Returns the loss, the parameter tensor it depends on and the rest of the
    /// pass (the mean E_mean, E_var and field loss, plans, end states).
    #[allow(clippy::too_many_arguments)]
    fn forward(
        &self,
        model: &mut Model,
        ci: usize,
        herds: &Herds,
        f: usize,
        w: usize,
        theta: &[f64],
        rng: &mut ChaCha8Rng,
    ) -> Result<(Tensor<1>, Tensor<1>, Forward)> {
        let (cfg, clip) = (self.cfg, self.clips[ci]);
        let (guidance, stencil) = &self.per_clip[ci];
        // Weights of (E_mean, E_var) in the back-propagated loss: the paper's split takes
        // E_var's gradient in a second pass; field matching replaces E_mean.
        let still_fields = cfg.still.is_some() && cfg.loss != LossKind::Paper;
        let weights = match (cfg.loss, cfg.split_gradients) {
            // A still's field objective is its density term (below) and E_var; its paper
            // objective E_mean against U = N(D) (eq. 10–11, no velocity) and E_var, as a video's.
            _ if still_fields => (0.0, (!cfg.split_gradients) as u8 as f64 * cfg.var_weight),
            // (`auto` is refused in `FitRun::new`.)
            (LossKind::Fields | LossKind::Ensemble | LossKind::Auto, _) => (0.0, cfg.var_weight),
            (LossKind::Paper, true) => (1.0, 0.0),
            (LossKind::Paper, false) => (1.0, cfg.var_weight),
        };
        let th = thetas_tensor(theta, &self.ad).require_grad();
        let forces = ForceTensors::new(&th.clone().narrow(0, 0, N_PARAMS), &model.params.constants);
        let mut total: Option<Tensor<1>> = None;
        let (mut em, mut ev, mut ef) = (0.0, 0.0, 0.0);
        let replicas = herds.rows.len();
        let mut all_plans = Vec::with_capacity(replicas);
        let mut ends = Vec::with_capacity(replicas);
        // Per step, each replica's end-of-step state (for the ensemble loss).
        let mut per_step: Vec<Vec<HerdState>> = vec![Vec::new(); w];
        let live: Vec<usize> = (0..replicas)
            .filter(|&r| !herds.rows[r].is_empty())
            .collect();
        let kr = live.len() as f64;
        for &r in &live {
            let mut state = HerdState::from_rows(&herds.rows[r], &self.ad);
            let mut plans = Vec::with_capacity(w);
            for (s, slot) in per_step.iter_mut().enumerate() {
                let plan = plan_step(
                    model,
                    clip,
                    guidance,
                    stencil,
                    cfg.beta,
                    cfg.cell_mean,
                    &state,
                    f + s,
                    rng,
                )?;
                let fz = self.step_forces(&forces, &th, &plan.1, model);
                let (next, loss, e_m, e_v) =
                    window_loss(model, &fz, state, std::slice::from_ref(&plan), weights)?;
                plans.push(plan);
                state = next;
                em += e_m / (w as f64 * kr);
                ev += e_v / (w as f64 * kr);
                let loss = match cfg.loss {
                    _ if still_fields => {
                        let dl = density_loss(clip, &state, f + s + 1)?;
                        ef += read_vec(&dl.clone().detach())?[0] / (w as f64 * kr);
                        loss + dl.mul_scalar(cfg.density_weight)
                    }
                    LossKind::Fields | LossKind::Auto => {
                        let fl = fields_loss_weighted(clip, &state, f + s + 1, cfg.density_weight)?;
                        ef += read_vec(&fl.clone().detach())?[0] / (w as f64 * kr);
                        loss + fl
                    }
                    LossKind::Ensemble => {
                        slot.push(state.clone());
                        loss
                    }
                    LossKind::Paper if cfg.still.is_some() => {
                        // Logged only: the still's density term, off the autodiff graph.
                        let dl = density_loss(clip, &state.clone().detach(), f + s + 1)?;
                        ef += read_vec(&dl)?[0] / (w as f64 * kr);
                        loss
                    }
                    LossKind::Paper => {
                        // Logged only: evaluated off the autodiff graph.
                        let fl = fields_loss_weighted(
                            clip,
                            &state.clone().detach(),
                            f + s + 1,
                            cfg.density_weight,
                        )?;
                        ef += read_vec(&fl)?[0] / (w as f64 * kr);
                        loss
                    }
                };
                add(&mut total, loss.div_scalar(kr));
            }
            all_plans.push(plans);
            ends.push(state);
        }
        if cfg.loss == LossKind::Ensemble {
            for (s, states) in per_step.iter().enumerate() {
                let l = ensemble_loss_weighted(clip, states, f + s + 1, cfg.density_weight)?;
                ef += read_vec(&l.clone().detach())?[0] / w as f64;
                add(&mut total, l);
            }
        }
        let loss = total
            .ok_or_else(|| Error::invalid("empty window"))?
            .div_scalar(w as f64);
        let fwd = Forward {
            e_mean: em,
            e_var: ev,
            e_fields: ef,
            live,
            plans: all_plans,
            ends,
        };
        Ok((loss, th, fwd))
    }

    /// The window's gradient: of the forward loss, and with the paper's split (§6.1) the
    /// alignment parameters' from E_var alone, in a second pass over the same (replayed)
    /// decisions and targets.
    fn gradient(
        &self,
        model: &Model,
        herds: &Herds,
        loss: Tensor<1>,
        th: &Tensor<1>,
        fwd: &Forward,
        theta: &[f64],
    ) -> Result<Vec<f64>> {
        let cfg = self.cfg;
        let mut g = grad_of(loss, th)?;
        if !(cfg.split_gradients && (cfg.loss == LossKind::Paper || cfg.still.is_some())) {
            return Ok(g);
        }
        let kr = fwd.live.len() as f64;
        let w = fwd.plans[0].len();
        let th2 = thetas_tensor(theta, &self.ad).require_grad();
        let c = &model.params.constants;
        let forces2 = ForceTensors::new(&th2.clone().narrow(0, 0, N_PARAMS), c);
        let mut total2: Option<Tensor<1>> = None;
        for (k, &r) in fwd.live.iter().enumerate() {
            let mut s2 = HerdState::from_rows(&herds.rows[r], &self.ad);
            for (dec, tgt) in &fwd.plans[k] {
                s2 = model.step(&self.step_forces(&forces2, &th2, tgt, model), &s2, dec)?;
                let l = step_loss(&s2.hx, &s2.hy, tgt).e_var;
                add(&mut total2, l.div_scalar(kr));
            }
        }
        let loss2 = total2
            .ok_or_else(|| Error::invalid("empty window"))?
            .div_scalar(w as f64);
        let gvar = grad_of(loss2, &th2)?;
        for k in 0..theta.len() / N_PARAMS {
            for p in ALIGNMENT {
                g[k * N_PARAMS + p] = cfg.var_weight * gvar[k * N_PARAMS + p];
            }
        }
        Ok(g)
    }

    /// The forces of one step: `shared` (the one parameter set), or in a zone fit each agent's
    /// zone's set, chosen by the cell the plan recorded for it ([`ForceTensors::zoned`]).
    fn step_forces(
        &self,
        shared: &ForceTensors,
        th: &Tensor<1>,
        tgt: &StepTarget,
        model: &Model,
    ) -> ForceTensors {
        match self.zones {
            None => shared.clone(),
            Some(z) => {
                let zone: Vec<usize> = tgt.cell.iter().map(|&c| z.zone_of_cell(c)).collect();
                ForceTensors::zoned(th, &zone, &model.params.constants)
            }
        }
    }
}
