//! The settings of a fit ([`FitConfig`]), the objective ([`LossKind`]) and their checks.

use crate::backend::{Compute, Precision};
use crate::data::ClipFields;
use crate::error::{check_counts, Error, Result};
use crate::herd::boundary::BoundaryChoice;
use crate::herd::guidance::{check_guidance_scale, GUIDANCE_SCALE};
use crate::herd::start::Settle;
use crate::optim::Optimizer;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Settings of a fit (recorded as `settings` in the fitted parameter set's provenance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitConfig {
    /// Unrolled steps per gradient update (1 = the paper's greedy per-frame scheme).
    pub window: usize,
    pub epochs: usize,
    /// β of eq. 11.
    pub beta: f64,
    /// λ_var: weight of E_var.
    pub var_weight: f64,
    pub lr: f64,
    pub optimizer: Optimizer,
    /// Frames of the clip used (start..end, end exclusive).
    pub frames: Range<usize>,
    pub seed: u64,
    /// Density error Σ|ρ' − ρ| / Σρ above which the population is rebalanced.
    pub density_threshold: f64,
    /// Size of the random step taken when the gradient vanishes.
    pub zero_grad_step: f64,
    pub precision: Precision,
    /// The paper's split (§6.1): alignment parameters follow ∇E_var, the others ∇E_mean.
    /// Off: every parameter follows ∇(E_mean + λ E_var).
    pub split_gradients: bool,
    /// E_mean on cell means rather than per agent (see [`crate::herd::fit::loss::StepTarget::cell_mean`]).
    pub cell_mean: bool,
    /// The objective: the paper's E_mean + λ E_var, or field matching.
    #[serde(default)]
    pub loss: LossKind,
    /// burn's balanced gradient checkpointing (less memory for long windows, more time).
    #[serde(default)]
    pub checkpointing: bool,
    /// How each epoch's starting herd is settled (see [`crate::herd::start::settle`]).
    #[serde(default)]
    pub settle: Settle,
    /// Independent herds simulated side by side from the same fields (each its own sampling and
    /// noise); the losses are averaged over them, and `--loss ensemble` compares their mean.
    #[serde(default = "one_replica")]
    pub replicas: usize,
    /// σ (cells) of the smoothing that turns the clip's momentum into leader guidance
    /// ([`crate::herd::guidance::guidance_field`]).
    #[serde(
        default = "default_guidance_scale",
        with = "crate::limits::infinite_ok"
    )]
    pub guidance_scale: f64,
    /// How the forces of eq. 3–5 are computed in the training loop (the fused op by default; not
    /// written when it is the default, so checkpoints keep their bytes).
    #[serde(
        default,
        skip_serializing_if = "crate::herd::sim::ForceKernel::is_fused"
    )]
    pub force_kernel: crate::herd::sim::ForceKernel,
    /// Where the tensors live (not written when `cpu`, so checkpoints keep their bytes).
    #[serde(default, skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
    /// The global phase before the gradient refinement ([`crate::herd::fit::global`]; not
    /// written when off, so checkpoints of single-start fits keep their bytes).
    #[serde(default, skip_serializing_if = "GlobalPhase::is_off")]
    pub global: GlobalPhase,
    /// Parameters held at their start value, by name (`cohesion.angular`, …, as
    /// [`crate::herd::params::param_names`]): the ablation of angular perception (§7.2.2) holds
    /// the four angular ranges at 1 (Φ = π). Not written when empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub frozen: Vec<String>,
    /// Weight of the density term of the field-matching and ensemble objectives (0: the ablation
    /// of density matching, §7.2.3; in the paper's objective the density term is β of eq. 11).
    /// Not written when 1.
    #[serde(default = "unit_weight", skip_serializing_if = "is_unit_weight")]
    pub density_weight: f64,
    /// A fit from a single image (paper §7.2.4, [`crate::herd::fit::still`]): the clip is a
    /// one-frame clip repeated as a stationary target; the loss is the density match (`loss`
    /// fields) or E_mean towards the density gradient (`loss` paper), plus λ_var E_var, over the
    /// steps after `settle`. Not written when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub still: Option<super::still::StillConfig>,
    /// Tracked animals, one `herdfit.tracks/1` file per clip in clip order (`fit --tracks`,
    /// [`crate::herd::fit::anchor`]): every window starts from the animals tracked at its first
    /// frame. Empty: windows carry the herd drawn from the fields. Not written when empty.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub tracks: Vec<std::path::PathBuf>,
    /// The clips' open boundary ([`crate::herd::boundary`]): `auto` (the gates the clip's flux
    /// shows; closed when nothing crosses its edge), `closed`, or a `herdfit.boundary/1` file.
    /// Agents that leave the grid are removed between windows and the count's shortfall enters
    /// at the entry gates. Not written when `auto`.
    #[serde(default, skip_serializing_if = "is_auto")]
    pub boundary: BoundaryChoice,
}

fn is_auto(b: &BoundaryChoice) -> bool {
    *b == BoundaryChoice::Auto
}

fn unit_weight() -> f64 {
    1.0
}

fn is_unit_weight(w: &f64) -> bool {
    *w == 1.0
}

/// Settings of the multi-start global phase (issue #15 item 3, [`crate::herd::fit::global`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GlobalPhase {
    /// Candidates: the given start, then `starts − 1` points of a Latin hypercube over the
    /// parameter box; each refined by the gradient fit. 1: no global phase (the plain fit).
    pub starts: usize,
    /// Fraction of the frames (the last ones) held out of every refinement; the candidates are
    /// ranked by the objective on them.
    pub holdout: f64,
}

impl Default for GlobalPhase {
    fn default() -> Self {
        GlobalPhase {
            starts: 1,
            holdout: 0.25,
        }
    }
}

impl GlobalPhase {
    /// No global phase: one start, the plain fit on every frame.
    pub fn is_off(&self) -> bool {
        self.starts <= 1
    }

    /// Checks the ranges; errors name `global.starts` / `global.holdout`.
    pub fn check(&self) -> Result<()> {
        if self.starts == 0 || self.starts > 64 {
            return Err(Error::config(
                "global.starts",
                format!("{} is out of range 1..=64", self.starts),
            ));
        }
        if !(self.holdout.is_finite() && self.holdout > 0.0 && self.holdout < 1.0) {
            return Err(Error::config(
                "global.holdout",
                format!("{} is out of range (0, 1)", self.holdout),
            ));
        }
        Ok(())
    }
}

fn default_guidance_scale() -> f64 {
    GUIDANCE_SCALE
}

fn one_replica() -> usize {
    1
}

/// What the fit minimises.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LossKind {
    /// E_mean (eq. 7) + λ_var E_var (eq. 8) against the target field U (eq. 10–11); on a still
    /// (no velocity) U = N(D), the paper's β = 1 "match on the density field alone" (§6.1).
    Paper,
    /// Field matching: after every step, the simulated density and momentum fields (bilinear
    /// splatting of the agents and of their velocities) against the clip's,
    /// Σ(ρ' − Kρ)² / Σ(Kρ)² + Σ‖ρ'V' − K(ρV)‖² / Σ‖K(ρV)‖², plus λ_var E_var, where K blurs the
    /// clip's box-binned fields as splatting blurs points ([`crate::herd::fit::target::blur_like_splat`]).
    /// The default of [`FitConfig`] (the fitting routines), and what `auto` keeps where it cannot
    /// choose: on synthetic clips it moves the fit towards the truth's behaviour where the paper's
    /// E_mean moves it away (RESULTS.md, the fit). On a still (no velocity) only the density
    /// term, plus λ_var E_var.
    #[default]
    Fields,
    /// Field matching of the *expected* simulated fields: the replicas' mean fields against the
    /// clip's, minus the replicas' own spread (an unbiased estimate of ‖E[ρ'] − ρ‖², see
    /// [`crate::herd::fit::ensemble_loss`]), plus λ_var E_var. Needs `replicas` ≥ 2.
    Ensemble,
    /// `fields` or `paper`, chosen per clip by a fit job on its own frames: each fitted on the
    /// first half, the one whose set predicts the second half better kept
    /// ([`crate::herd::fit::choose`]). The default of `herdfit fit` and of [`super::FitJob`];
    /// the fitting routines themselves take a chosen objective.
    Auto,
}

enum_names!(LossKind { Paper = "paper", Fields = "fields", Ensemble = "ensemble", Auto = "auto" });

/// Why a fitting routine refuses `auto`.
pub const AUTO_UNRESOLVED: &str =
    "auto is chosen by a fit job (herdfit fit, FitJob); this routine takes fields, paper or ensemble";

/// Why a still (one-frame clip) refuses the ensemble objective.
const STILL_ENSEMBLE: &str = "a still image has no velocity: fit it by its density term \
     (fields) or by the paper's E_mean towards the density gradient (paper), not by the ensemble";

pub use crate::herd::params::ALIGNMENT;

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            window: 4,
            epochs: 8,
            beta: 0.7,
            var_weight: 1.0,
            lr: 0.02,
            optimizer: Optimizer::Adam,
            frames: 0..0,
            seed: 0,
            density_threshold: 0.3,
            zero_grad_step: 0.02,
            precision: Precision::F32,
            split_gradients: true,
            cell_mean: false,
            loss: LossKind::Fields,
            checkpointing: false,
            settle: Settle::default(),
            replicas: 1,
            guidance_scale: GUIDANCE_SCALE,
            force_kernel: crate::herd::sim::ForceKernel::Fused,
            device: Compute::Cpu,
            global: GlobalPhase::default(),
            frozen: Vec::new(),
            density_weight: 1.0,
            still: None,
            tracks: Vec::new(),
            boundary: BoundaryChoice::Auto,
        }
    }
}

impl FitConfig {
    /// Windows of `self.window` steps in one epoch over `frames` of each of `clips` clips.
    pub fn windows_per_epoch(&self, frames: &Range<usize>, clips: usize) -> usize {
        (frames.end - frames.start - 1).div_ceil(self.window) * clips
    }

    /// Checks the settings on their own: ranges, and the ensemble objective's replicas. Errors
    /// name the key.
    pub fn check(&self) -> Result<()> {
        if self.frames.end < self.frames.start + 2 {
            return Err(Error::config(
                "frames",
                format!(
                    "{}..{} must span at least 2 frames",
                    self.frames.start, self.frames.end
                ),
            ));
        }
        if self.still.is_some() {
            // A still is fitted by its density term (fields) or by E_mean towards the density
            // gradient (paper), with E_var: the ensemble needs velocities (checked before its
            // replicas, so that the error names what is wrong with it).
            if self.loss == LossKind::Ensemble {
                return Err(Error::config("loss", STILL_ENSEMBLE));
            }
            if !self.tracks.is_empty() {
                return Err(Error::config(
                    "tracks",
                    "a still image is one frame: there are no windows for tracks to start",
                ));
            }
        }
        if self.loss == LossKind::Ensemble && self.replicas < 2 {
            return Err(Error::config(
                "replicas",
                "{loss} ensemble compares several herds: set 2 or more",
            ));
        }
        if self.replicas == 0 || self.replicas > 64 {
            return Err(Error::config(
                "replicas",
                format!("{} is out of range 1..=64", self.replicas),
            ));
        }
        check_counts(&[("window", self.window), ("epochs", self.epochs)])?;
        crate::limits::check_count("window", self.window, crate::limits::MAX_STEPS)?;
        crate::limits::check_count("epochs", self.epochs, crate::limits::MAX_ITERATIONS)?;
        check_guidance_scale(self.guidance_scale)?;
        self.global.check()?;
        for (key, v, lo, hi) in [
            ("beta", self.beta, 0.0, 1.0),
            // Weights of a loss term: beyond 1e6 the others vanish in round-off (issue #47).
            ("var_weight", self.var_weight, 0.0, 1e6),
            ("lr", self.lr, 1e-12, 1.0),
            (
                "density_threshold",
                self.density_threshold,
                0.0,
                crate::limits::MAX_DENSITY,
            ),
            ("zero_grad_step", self.zero_grad_step, 0.0, 1e6),
            ("density_weight", self.density_weight, 0.0, 1e6),
        ] {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(Error::config(key, format!("{v} is out of range")));
            }
        }
        self.frozen_indices()?;
        if let Some(s) = &self.still {
            s.check()?;
        }
        self.settle.check()
    }

    /// The indices of the `frozen` parameters; an unknown name is an error naming `frozen`.
    pub fn frozen_indices(&self) -> Result<Vec<usize>> {
        let names = crate::herd::params::param_names();
        self.frozen
            .iter()
            .map(|n| {
                names.iter().position(|m| m == n).ok_or_else(|| {
                    Error::config(
                        "frozen",
                        format!("'{n}' is not a parameter (one of {})", names.join(", ")),
                    )
                })
            })
            .collect()
    }

    /// [`FitConfig::check`], then the settings against a clip: the frames inside it, a herd in
    /// them and at the first.
    pub fn check_clip(&self, clip: &ClipFields) -> Result<()> {
        self.check()?;
        let f = clip.frames();
        if self.frames.end > f {
            return Err(Error::config(
                "frames",
                format!(
                    "{}..{} is out of range: the clip has frames 0..{f}",
                    self.frames.start, self.frames.end
                ),
            ));
        }
        let steps = self.frames.end.saturating_sub(self.frames.start + 1);
        if self.window > steps {
            return Err(Error::config(
                "window",
                format!(
                    "{} steps is longer than the {steps} steps of frames {}..{}",
                    self.window, self.frames.start, self.frames.end
                ),
            ));
        }
        let total: f64 = (self.frames.start..self.frames.end)
            .map(|k| clip.count(k))
            .sum();
        if total < 1.0 {
            return Err(Error::invalid(
                "the clip's density is zero everywhere in the frames used: nothing to fit",
            ));
        }
        if clip.count(self.frames.start) < 1.0 {
            return Err(Error::config(
                "frames",
                format!(
                    "frame {} of the clip holds no agents: start the fit where the herd is",
                    self.frames.start
                ),
            ));
        }
        Ok(())
    }
}
