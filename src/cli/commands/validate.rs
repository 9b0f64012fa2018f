//! `herdfit validate`: flags → [`ValidateJob`] → [`zone_report::run_either`] → the report's Markdown.

use crate::cli::args::{choice, parse_range, with_flags, DeviceArg, MEASURES};
use crate::cli::paths::{InDir, InFile, InFileOrWord, OutDir};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::fit::{Settle, GUIDANCE_SCALE};
use crate::herd::validate::{zone_report, Measures, ValidateConfig, ValidateJob};
use clap::Args;

#[derive(Args, Debug)]
pub struct ValidateArgs {
    #[arg(value_name = "CLIP/")]
    pub clip: InDir,
    /// The parameter set to validate (e.g. the fit's output), or a zone fit's parameter-set
    /// bundle (validated zone by zone, each agent with its zone's set and speed).
    #[arg(long, value_name = "P.json")]
    pub params: InFile,
    /// A baseline to compare with (e.g. the fit's starting parameters); with a bundle, another
    /// bundle of the same zones or one set played in every zone.
    #[arg(long, value_name = "P0.json")]
    pub baseline: Option<InFile>,
    /// Fraction of the clip before the held-out part.
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub split: f64,
    /// Coarse grid (cells per side) of the density and velocity errors.
    #[arg(long, alias = "grid", value_name = "N", default_value_t = 10)]
    pub coarse_grid: usize,
    /// Simulations per parameter set (averaged).
    #[arg(long, value_name = "K", default_value_t = 3)]
    pub seeds: usize,
    /// Iterations settling the starting herd into the model's spacing (0: none).
    #[arg(long, value_name = "N", default_value_t = Settle::default().iterations)]
    pub settle: usize,
    /// Start the herd this many frames before the held-out part (from those fields) and simulate
    /// through them unrecorded (0: start from the fields of the first held-out frame).
    #[arg(long, value_name = "F", default_value_t = 0)]
    pub warmup: usize,
    /// Draw the herd afresh from the clip's fields every F frames of the held-out part (0: one
    /// run through it, the paper's protocol): scores short-term prediction from where the
    /// animals are.
    #[arg(long, value_name = "F", default_value_t = 0)]
    pub horizon: usize,
    /// σ (cells) of the Gaussian that smooths the clip's momentum into the leaders' guidance
    /// (0: each cell's own mean velocity; inf: the herd's mean direction everywhere).
    #[arg(long, value_name = "S", default_value_t = GUIDANCE_SCALE, allow_hyphen_values = true)]
    pub guidance_scale: f64,
    /// Compare the seeds' mean prediction with the clip (counts, momenta and each measure
    /// averaged over the seeds frame by frame) instead of averaging each seed's own errors.
    #[arg(long)]
    pub ensemble_mean: bool,
    /// Tracked animals of the clip (a herdfit.tracks/1 CSV in its body lengths and frames, as for
    /// `fit --tracks`): each run (each piece, with --horizon) starts from the animals tracked at
    /// its first frame instead of a herd drawn from the fields.
    #[arg(long, value_name = "TRACKS.csv")]
    pub tracks: Option<InFile>,
    /// The clip's open boundary: `auto` (entry and exit cells from the video's flux across the
    /// grid's edge; closed when nothing crosses it), `closed`, or a herdfit.boundary/1 file.
    /// Agents leaving the grid are removed and the count's shortfall enters at the entry cells
    #[arg(long, value_name = "auto|closed|FILE", default_value = "auto")]
    pub boundary: InFileOrWord,
    /// Held-out frames a..b (b exclusive) instead of --split to the end (e.g. the reference's
    /// logging protocol: 0..101, 100 frames after the clip's first)
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    /// Measures reported
    #[arg(long, value_parser = choice::<Measures>(MEASURES), default_value_t = Measures::Herdfit)]
    pub measures: Measures,
    /// Skip the side-by-side video.
    #[arg(long)]
    pub no_video: bool,
    #[command(flatten)]
    pub device: DeviceArg,
    /// Output report folder.
    #[arg(long, value_name = "REPORT/")]
    pub out: OutDir,
}

pub fn exec(a: ValidateArgs) -> Result<()> {
    let boundary = crate::cli::args::boundary(&a.boundary)?;
    let job = ValidateJob {
        clip: a.clip.into(),
        params: a.params.into(),
        baseline: a.baseline.map(Into::into),
        out: a.out.into(),
        video: !a.no_video,
        config: ValidateConfig {
            split: a.split,
            coarse_grid: a.coarse_grid,
            seeds: a.seeds,
            settle: Settle::with_iterations(a.settle),
            warmup: a.warmup,
            guidance_scale: a.guidance_scale,
            ensemble_mean: a.ensemble_mean,
            horizon: a.horizon,
            tracks: a.tracks.map(Into::into),
            boundary,
            frames: a.frames.map(|(x, y)| [x, y]),
            measures: a.measures,
            device: a.device.device,
        },
    };
    // A zone fit's bundle (herdfit.param-sets/1) is validated zone by zone.
    let md = zone_report::run_either(&job, &mut Bars::default()).map_err(|e| with_flags(e, &[]))?;
    print!("{md}");
    println!("wrote {}", job.out.display());
    Ok(())
}
