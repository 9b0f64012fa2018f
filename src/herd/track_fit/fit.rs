//! The track fit's loop: epochs of windows in random order, each window's loss (mean squared
//! position error + w_h × mean squared heading error against the tracks, [`window_loss`])
//! back-propagated through its steps to θ, one optimiser step per window; the speed model of
//! eq. 6 learnt from the tracks first ([`learn_speed`]).

use super::config::TrackFitConfig;
use super::rollout::{window_loss, TrackClip, Window};
use super::speed::{learn_speed, SpeedFit};
use crate::backend::cpu_device;
use crate::error::{Error, Result};
use crate::herd::params::{Params, N_PARAMS};
use crate::herd::sim::{read_vec, theta_tensor, Decide, ForceTensors};
use crate::optim::OptState;
use burn::tensor::{Device, Tensor};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

/// One window of the training log.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrackLogRow {
    pub epoch: usize,
    pub clip: usize,
    /// The window's first frame.
    pub frame: usize,
    pub loss: f64,
    /// Root mean squared position error over the window's scored samples (BL).
    pub pos_rmse: f64,
    /// Root mean squared |d − d̂| over its scored headings.
    pub head_rmse: f64,
    /// Scored position samples.
    pub samples: usize,
    #[serde(skip)]
    pub theta: [f64; N_PARAMS],
}

/// Result of a track fit.
#[derive(Clone, Debug)]
pub struct TrackFitResult {
    /// The start set with the fitted forces and the speed model the fit ran with.
    pub params: Params,
    pub start: [f64; N_PARAMS],
    pub log: Vec<TrackLogRow>,
    /// How the speed model was learnt (`None`: the start set's was kept).
    pub speed: Option<SpeedFit>,
}

fn epoch_rng(seed: u64, epoch: usize) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ (epoch as u64 + 1).wrapping_mul(0xA076_1D64_78BD_642F))
}

/// The clips ready to fit: every clip's model takes the speed model learnt from all the clips'
/// tracks in their frames (or `init`'s), `init`'s constants and `cfg`'s force kernel. Returns
/// the parameter set the fit starts from (with that speed model) and how it was learnt.
pub fn prepare(
    clips: &mut [TrackClip],
    init: &Params,
    cfg: &TrackFitConfig,
) -> Result<(Params, Option<SpeedFit>)> {
    let mut start = init.clone();
    let fit = match cfg.learn_speed {
        true => {
            let sets: Vec<_> = clips
                .iter()
                .map(|c| (&c.tracks, c.frames.clone()))
                .collect();
            let (m, f) = learn_speed(&sets, init.constants.perception_radius, &init.speed)?;
            start.speed = m;
            Some(f)
        }
        false => None,
    };
    for c in clips.iter_mut() {
        c.model.params = start.clone();
        c.model.force_kernel = cfg.force_kernel;
    }
    Ok((start, fit))
}

/// The windows of one epoch over every clip, in random order (`rng`): each clip's windows start
/// every `stride` from a random offset.
pub fn epoch_windows(clips: &[TrackClip], cfg: &TrackFitConfig, rng: &mut impl Rng) -> Vec<Window> {
    let mut out = Vec::new();
    for (i, c) in clips.iter().enumerate() {
        let (steps, stride) = (cfg.steps(c.tracks.fps), cfg.stride_frames(c.tracks.fps));
        let offset = rng.gen_range(0..stride);
        out.extend(c.windows(i, steps, stride, offset));
    }
    out.shuffle(rng);
    out
}

/// The gradient of `loss` with respect to `theta` (zeros where none reaches it).
fn gradient(loss: Tensor<1>, theta: &Tensor<1>) -> Result<[f64; N_PARAMS]> {
    let grads = loss.backward();
    let mut g = [0.0; N_PARAMS];
    if let Some(t) = theta.grad(&grads) {
        g.copy_from_slice(&read_vec(&t)?);
    }
    Ok(g)
}

/// One window's loss value, counts and gradient at `theta` with live decisions from `rng`.
struct Probe {
    loss: f64,
    pos_sq: f64,
    n_pos: usize,
    head_sq: f64,
    n_head: usize,
    grad: [f64; N_PARAMS],
}

fn probe(
    clips: &[TrackClip],
    w: &Window,
    theta: &[f64; N_PARAMS],
    cfg: &TrackFitConfig,
    ad: &Device,
    rng: &mut ChaCha8Rng,
) -> Result<Option<Probe>> {
    let clip = &clips[w.clip];
    let th = theta_tensor(theta, ad).require_grad();
    let forces = ForceTensors::new(&th, &clip.model.params.constants);
    let decide = Decide::Live { rng, record: None };
    let Some(l) = window_loss(clip, w, &cfg.scoring(), &forces, ad, decide)? else {
        return Ok(None);
    };
    let loss = read_vec(&l.loss.clone().detach())?[0];
    let grad = gradient(l.loss, &th)?;
    if !loss.is_finite() || grad.iter().any(|g| !g.is_finite()) {
        return Err(Error::invalid(format!(
            "clip #{}, window from frame {} at θ = {theta:?}: the loss ({loss}) or its \
             gradient is not finite; likely cause: extreme positions or speeds in the tracks",
            w.clip, w.start
        )));
    }
    Ok(Some(Probe {
        loss,
        pos_sq: l.pos_sq,
        n_pos: l.n_pos,
        head_sq: l.head_sq,
        n_head: l.n_head,
        grad,
    }))
}

/// Fits θ to the tracks of `clips` (prepared by [`prepare`]) from `start`'s values.
/// `progress(epoch, window, loss)` is called after every window.
pub fn fit_tracks(
    clips: &[TrackClip],
    start: &Params,
    cfg: &TrackFitConfig,
    mut progress: impl FnMut(usize, usize, f64),
) -> Result<(Params, Vec<TrackLogRow>)> {
    cfg.check()?;
    let ad = cpu_device(cfg.precision)?.autodiff();
    let frozen = cfg.frozen_indices()?;
    let mut theta = start.to_vec();
    let mut opt = OptState::new(N_PARAMS);
    let mut log = Vec::new();
    for epoch in 0..cfg.epochs {
        let mut rng = epoch_rng(cfg.seed, epoch);
        let windows = epoch_windows(clips, cfg, &mut rng);
        // The step size decays linearly to 10 % over the epochs.
        let lr = cfg.lr * (1.0 - 0.9 * epoch as f64 / cfg.epochs as f64);
        for (i, w) in windows.iter().enumerate() {
            let Some(p) = probe(clips, w, &theta, cfg, &ad, &mut rng)? else {
                continue;
            };
            let before = theta;
            crate::optim::step(
                cfg.optimizer,
                &mut theta,
                &p.grad,
                &mut opt,
                lr,
                cfg.zero_grad_step,
                &mut rng,
            );
            Params::clamp_vec(&mut theta);
            for &j in &frozen {
                theta[j] = before[j];
            }
            log.push(TrackLogRow {
                epoch,
                clip: w.clip,
                frame: w.start,
                loss: p.loss,
                pos_rmse: (p.pos_sq / p.n_pos as f64).sqrt(),
                head_rmse: (p.head_sq / p.n_head.max(1) as f64).sqrt(),
                samples: p.n_pos,
                theta,
            });
            progress(epoch, i, p.loss);
        }
    }
    Ok((start.with_vec(&theta), log))
}

/// Each window's (loss, gradient) over one epoch at `params` without updates, with `cfg.seed`,
/// in time order: the same seed gives the same windows and noise (common random numbers). The probe of the
/// identifiability estimate ([`crate::optim::curvature`]), and with [`mean_loss`] the objective
/// of a set.
pub fn window_gradients(
    clips: &[TrackClip],
    params: &Params,
    cfg: &TrackFitConfig,
) -> Result<Vec<(f64, [f64; N_PARAMS])>> {
    let ad = cpu_device(cfg.precision)?.autodiff();
    let mut rng = epoch_rng(cfg.seed, 0);
    let mut windows = epoch_windows(clips, cfg, &mut rng);
    // In time order: the estimate's batch means of consecutive windows absorb the correlation
    // of overlapping windows.
    windows.sort_by_key(|w| (w.clip, w.start));
    let theta = params.to_vec();
    let mut out = Vec::with_capacity(windows.len());
    for w in &windows {
        if let Some(p) = probe(clips, w, &theta, cfg, &ad, &mut rng)? {
            out.push((p.loss, p.grad));
        }
    }
    if out.is_empty() {
        return Err(Error::invalid("no window of the tracks scores any animal"));
    }
    Ok(out)
}

/// The objective of `params` on the tracks: the mean window loss over one epoch with `cfg.seed`.
pub fn mean_loss(clips: &[TrackClip], params: &Params, cfg: &TrackFitConfig) -> Result<f64> {
    let w = window_gradients(clips, params, cfg)?;
    Ok(w.iter().map(|(l, _)| l).sum::<f64>() / w.len() as f64)
}
