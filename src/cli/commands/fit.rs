//! `herdfit fit`: flags → [`FitJob`] → [`run`] → the summary.

use super::fit_objective::{
    default_leaders, default_rollout, Objective, LEADERS, OBJECTIVES, ROLLOUTS, SPEEDS,
};
use crate::backend::Precision;
use crate::cli::args::{
    choice, parse_range, with_flags, DeviceArg, FIT_LOSSES, OPTIMIZERS, PRECISIONS,
};
use crate::cli::paths::{InDir, InFile, InFileOrWord, OutFile, StateDir};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::fit::job::{run, FitJob};
use crate::herd::fit::{
    FitConfig, GlobalPhase, LossKind, Optimizer, Settle, UncertaintyConfig, GUIDANCE_SCALE,
};
use crate::herd::track_fit::{Leaders, Rollout, Speeds, TrackFitConfig};
use clap::Args;

/// The gradient descent's flags, shared by `fit` and `ablate`.
#[derive(Args, Debug)]
pub struct StepFlags {
    /// Unrolled steps per update (1 = the paper's greedy per-frame scheme).
    #[arg(long, value_name = "W", default_value_t = 4)]
    pub window: usize,
    #[arg(long, value_name = "E", default_value_t = 8)]
    pub epochs: usize,
    /// β of eq. 11 (density vs velocity in the target).
    #[arg(long, value_name = "B", default_value_t = 0.7)]
    pub beta: f64,
    /// λ_var, the weight of E_var.
    #[arg(long, value_name = "L", default_value_t = 1.0)]
    pub var_weight: f64,
    #[arg(long, value_name = "X", default_value_t = 0.02)]
    pub lr: f64,
    #[arg(long, value_parser = choice::<Optimizer>(OPTIMIZERS), default_value_t = Optimizer::Adam)]
    pub optimizer: Optimizer,
}

impl StepFlags {
    /// `cfg` with these settings.
    pub fn apply(&self, cfg: FitConfig) -> FitConfig {
        FitConfig {
            window: self.window,
            epochs: self.epochs,
            beta: self.beta,
            var_weight: self.var_weight,
            lr: self.lr,
            optimizer: self.optimizer,
            ..cfg
        }
    }
}

#[derive(Args, Debug)]
pub struct FitArgs {
    /// One clip, or several clips of the same kind of herd fitted jointly (paper §7.6).
    #[arg(value_name = "CLIP/", num_args = 1.., required = true)]
    pub clips: Vec<InDir>,
    /// Output parameter set (herdfit.params/1).
    #[arg(long, value_name = "PARAMS.json")]
    pub out: OutFile,
    /// Starting parameters; a generic start (every value 0.5) when omitted.
    #[arg(long, alias = "init", value_name = "P.json")]
    pub start: Option<InFile>,
    #[command(flatten)]
    pub steps: StepFlags,
    /// Frames used, a..b (b exclusive); all frames when omitted.
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Density error above which the population is rebalanced.
    #[arg(long, value_name = "E", default_value_t = 0.3)]
    pub density_threshold: f64,
    /// Every parameter follows ∇(E_mean + λ E_var) instead of the paper's split (alignment from
    /// E_var, the others from E_mean).
    #[arg(long)]
    pub joint_gradients: bool,
    /// E_mean on each cell's mean direction instead of every follower's (spread left to E_var).
    #[arg(long)]
    pub cell_mean: bool,
    /// Objective: matching the density and momentum fields, or the paper's losses, or the one of
    /// the two that predicts the clip better (auto). A still image (one frame) has no velocity:
    /// `fields` matches its density, `paper` steers each agent down the density difference
    /// (E_mean towards U = N(D), eq. 10–11); both add λ_var E_var
    #[arg(long, value_parser = choice::<LossKind>(FIT_LOSSES), default_value_t = LossKind::Auto)]
    pub loss: LossKind,
    /// Tracked animals of the clip (a herdfit.tracks/1 CSV in the clip's body lengths and frames:
    /// synth's trajectories.csv, import-tracks' tracks.csv), once per clip in clip order: every
    /// window then starts from the animals tracked at its first frame instead of the herd drawn
    /// from the fields, so the objective scores the model's steps from where the animals were
    #[arg(long, value_name = "TRACKS.csv")]
    pub tracks: Vec<InFile>,
    /// The clip's open boundary: `auto` (entry and exit cells from the video's flux across the
    /// grid's edge; closed when nothing crosses it), `closed`, or a herdfit.boundary/1 file.
    /// Agents leaving the grid are removed and the count's shortfall enters at the entry cells
    #[arg(long, value_name = "auto|closed|FILE", default_value = "auto")]
    pub boundary: InFileOrWord,
    /// Gradient checkpointing: less memory through long windows, more time (see BENCHMARKS.md).
    #[arg(long)]
    pub checkpointing: bool,
    /// Compute the forces with the tensor-op reference implementation instead of the fused op
    /// (the same values to round-off; slower).
    #[arg(long)]
    pub reference_forces: bool,
    /// Iterations settling each epoch's starting herd into the model's spacing (0: none).
    #[arg(long, value_name = "N", default_value_t = Settle::default().iterations)]
    pub settle: usize,
    /// Herds simulated side by side from the same fields (losses averaged; `--loss ensemble`
    /// compares their mean fields with the clip's).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub replicas: usize,
    /// Runs (seeds S, S+1, …) whose density and velocity errors, with the start and the fitted
    /// parameters, are averaged into the provenance's `evaluation` (one run is mostly noise).
    #[arg(long, value_name = "K", default_value_t = 4)]
    pub eval_seeds: usize,
    /// --loss auto: validation runs scoring each candidate objective on the second half
    #[arg(long, value_name = "K", default_value_t = FitJob::default().choice_seeds)]
    pub choice_seeds: usize,
    /// σ (cells) of the Gaussian that smooths the clip's momentum into the leaders' guidance
    /// (0: each cell's own mean velocity; inf: the herd's mean direction everywhere).
    #[arg(long, value_name = "S", default_value_t = GUIDANCE_SCALE, allow_hyphen_values = true)]
    pub guidance_scale: f64,
    #[arg(long, value_parser = choice::<Precision>(PRECISIONS), default_value_t = Precision::F32)]
    pub precision: Precision,
    #[command(flatten)]
    pub device: DeviceArg,
    /// Global phase: K candidate starts (the given one, then a Latin hypercube over the
    /// parameter box), each refined by the gradient fit, the best on held-out frames kept
    /// (1: the plain fit on every frame). Default 1; with --objective tracks 4, each refined by
    /// --start-epochs and ranked by the objective.
    #[arg(long, value_name = "K")]
    pub starts: Option<usize>,
    /// With --starts > 1: fraction of the frames (the last) held out of the refinements to rank
    /// the candidates.
    #[arg(long, value_name = "F", default_value_t = GlobalPhase::default().holdout)]
    pub holdout: f64,
    /// Write a checkpoint into DIR after every epoch.
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<StateDir>,
    /// Continue from DIR/checkpoint.json (same flags required).
    #[arg(long, requires = "checkpoint")]
    pub resume: bool,
    /// Training log CSV (default: next to --out, .log.csv).
    #[arg(long, value_name = "LOG.csv")]
    pub log: Option<OutFile>,
    /// Loss-curve PNG (default: next to --out, .loss.png).
    #[arg(long, value_name = "LOSS.png")]
    pub plot: Option<OutFile>,
    /// Skip the identifiability estimate at the fitted point (standard errors and determined
    /// directions, written as the set's `uncertainty`).
    #[arg(long)]
    pub no_uncertainty: bool,
    /// Seeds of the identifiability estimate (each probes the objective at 1 + 2×12 points).
    #[arg(long, value_name = "K", default_value_t = UncertaintyConfig::default().seeds)]
    pub uncertainty_seeds: usize,
    /// Parameters held at their start value (comma-separated names, e.g. cohesion.angular).
    #[arg(long, value_name = "NAME,…", value_delimiter = ',')]
    pub freeze: Vec<String>,
    /// Weight of the density term of the field-matching and ensemble objectives.
    #[arg(long, value_name = "W", default_value_t = 1.0)]
    pub density_weight: f64,
    /// One parameter set per zone (herdfit.zones/1: named polygons in the clip's coordinates
    /// covering every accessible cell once), learnt jointly; --out is then a parameter-set
    /// bundle (herdfit.param-sets/1) that author scenes' regions name sets of.
    #[arg(long, value_name = "ZONES.json")]
    pub zones: Option<InFile>,
    /// A still (one-frame clip, §7.2.4): steps simulated from the image before the objective is
    /// averaged.
    #[arg(long, value_name = "N", default_value_t = crate::herd::fit::still::StillConfig::default().settle)]
    pub still_settle: usize,
    /// A still: steps over which the density and direction-variance match is averaged.
    #[arg(long, value_name = "N", default_value_t = crate::herd::fit::still::StillConfig::default().average)]
    pub still_average: usize,
    /// Finite-difference step of the identifiability estimate.
    #[arg(long, value_name = "H", default_value_t = UncertaintyConfig::default().step)]
    pub uncertainty_step: f64,
    /// What the fit scores: the clip's fields, or each tracked animal's motion (the clip's
    /// tracks.csv or trajectories.csv, --tracks, or a tracks CSV in body lengths given as CLIP)
    #[arg(long, value_parser = choice::<Objective>(OBJECTIVES), default_value_t = Objective::Fields)]
    pub objective: Objective,
    /// --objective tracks: how a window's animals are rolled out
    #[arg(long, value_parser = choice::<Rollout>(ROLLOUTS), default_value_t = default_rollout())]
    pub rollout: Rollout,
    /// --objective tracks: window length (s) from the tracked animals
    #[arg(long, value_name = "S", default_value_t = TrackFitConfig::default().horizon)]
    pub horizon: f64,
    /// --objective tracks: the animals' speeds in the training windows
    #[arg(long, value_parser = choice::<Speeds>(SPEEDS), default_value_t = TrackFitConfig::default().speeds)]
    pub train_speeds: Speeds,
    /// --objective tracks: seconds between window starts (windows overlap below --horizon; 0:
    /// a window from every frame)
    #[arg(long, value_name = "S", default_value_t = TrackFitConfig::default().stride)]
    pub stride: f64,
    /// --objective tracks: weight (BL²) of the squared heading error beside the squared position
    /// error
    #[arg(long, value_name = "W", default_value_t = TrackFitConfig::default().heading_weight)]
    pub heading_weight: f64,
    /// --objective tracks: weight of the spacing term (the sorted nearest-neighbour distances,
    /// simulated against tracked, mean squared difference in BL²) beside the position error; 0:
    /// off
    #[arg(long, value_name = "W", default_value_t = TrackFitConfig::default().spacing_weight)]
    pub spacing_weight: f64,
    /// --objective tracks with --starts > 1: epochs of each candidate's short fit
    #[arg(long, value_name = "N", default_value_t = TrackFitConfig::default().start_epochs)]
    pub start_epochs: usize,
    /// --objective tracks: whether tracked animals may lead (§5.1)
    #[arg(long, value_parser = choice::<Leaders>(LEADERS), default_value_t = default_leaders())]
    pub leaders: Leaders,
}

pub fn exec(a: FitArgs) -> Result<()> {
    // The track objective's flags are checked whatever the objective (a value out of range is
    // refused, not silently ignored).
    TrackFitConfig {
        horizon: a.horizon,
        stride: a.stride,
        heading_weight: a.heading_weight,
        spacing_weight: a.spacing_weight,
        ..TrackFitConfig::default()
    }
    .check()
    .map_err(|e| {
        with_flags(
            e,
            &[
                ("horizon", "--horizon"),
                ("stride", "--stride"),
                ("heading_weight", "--heading-weight"),
                ("spacing_weight", "--spacing-weight"),
            ],
        )
    })?;
    let boundary = crate::cli::args::boundary(&a.boundary)?;
    let uncertainty = uncertainty_of(&a);
    let job = FitJob {
        clips: a.clips.into_iter().map(Into::into).collect(),
        start: a.start.map(Into::into),
        frames: a.frames.map(|(x, y)| x..y),
        config: a.steps.apply(FitConfig {
            frames: 0..0,
            seed: a.seed,
            density_threshold: a.density_threshold,
            zero_grad_step: 0.02,
            precision: a.precision,
            split_gradients: !a.joint_gradients,
            cell_mean: a.cell_mean,
            loss: a.loss,
            checkpointing: a.checkpointing,
            settle: Settle::with_iterations(a.settle),
            replicas: a.replicas,
            guidance_scale: a.guidance_scale,
            force_kernel: crate::herd::sim::ForceKernel::reference_if(a.reference_forces),
            device: a.device.device,
            global: GlobalPhase {
                starts: a.starts.unwrap_or(GlobalPhase::default().starts),
                holdout: a.holdout,
            },
            frozen: a.freeze,
            density_weight: a.density_weight,
            tracks: a.tracks.into_iter().map(Into::into).collect(),
            boundary,
            ..FitConfig::default()
        }),
        eval_seeds: a.eval_seeds,
        choice_seeds: a.choice_seeds,
        checkpoint: a.checkpoint.map(Into::into),
        resume: a.resume,
        out: a.out.into(),
        log: a.log.map(Into::into),
        plot: a.plot.map(Into::into),
        uncertainty,
        zones: a.zones.map(Into::into),
        still: crate::herd::fit::still::StillConfig {
            settle: a.still_settle,
            average: a.still_average,
        },
    };
    if job.zones.is_some() {
        let s = crate::herd::fit::zone_job::run_zones(&job, &mut Bars::default())
            .map_err(|e| with_flags(e, &[("global.starts", "--starts")]))?;
        print!("{s}");
        return Ok(());
    }
    let summary = run(&job, &mut Bars::default()).map_err(|e| {
        with_flags(
            e,
            &[
                ("split_gradients", "--joint-gradients"),
                ("uncertainty.seeds", "--uncertainty-seeds"),
                ("uncertainty.step", "--uncertainty-step"),
                ("global.starts", "--starts"),
                ("global.holdout", "--holdout"),
                ("frozen", "--freeze"),
                ("still.settle", "--still-settle"),
                ("still.average", "--still-average"),
            ],
        )
    })?;
    if let Some(w) = &summary.plot_warning {
        eprintln!("warning: no loss curve: {w}");
    }
    print!("{summary}");
    Ok(())
}

/// The identifiability estimate's flags (both objectives).
pub fn uncertainty_of(a: &FitArgs) -> UncertaintyConfig {
    UncertaintyConfig {
        enabled: !a.no_uncertainty,
        seeds: a.uncertainty_seeds,
        step: a.uncertainty_step,
        ..UncertaintyConfig::default()
    }
}
