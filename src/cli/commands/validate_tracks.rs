//! `herdfit validate-tracks`: flags → [`TrackEvalJob`] → [`run`] → the report's Markdown.

use super::fit_objective::{LEADERS, ROLLOUTS, SPEEDS};
use crate::backend::Precision;
use crate::cli::args::{choice, parse_range, with_flags, PRECISIONS};
use crate::cli::paths::{InDir, InFile, OutDir};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::track_fit::eval::TrackEvalConfig;
use crate::herd::track_fit::report::{run, TrackEvalJob};
use crate::herd::track_fit::{Leaders, Rollout, Speeds};
use clap::Args;

#[derive(Args, Debug)]
pub struct ValidateTracksArgs {
    /// Clip folders holding tracks (import-tracks' tracks.csv, synth's trajectories.csv) or
    /// tracks CSVs in body lengths, scored together.
    #[arg(value_name = "CLIP/", num_args = 1.., required = true)]
    pub inputs: Vec<InDir>,
    /// The parameter set to evaluate (e.g. from fit --objective tracks).
    #[arg(long, value_name = "P.json")]
    pub params: InFile,
    /// Another set to compare with (repeatable).
    #[arg(long, value_name = "B.json")]
    pub baseline: Vec<InFile>,
    /// Leave out the built-in generic (every value 0.5) and default sets.
    #[arg(long)]
    pub no_builtin: bool,
    /// Tracks files replacing the clips' own, one per clip in clip order.
    #[arg(long, value_name = "TRACKS.csv")]
    pub tracks: Vec<InFile>,
    /// Fraction of each clip before the scored frames (0: every frame is scored).
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub split: f64,
    /// The scored frames a..b (b exclusive), instead of --split.
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    /// Frames the speed model every set runs with is learnt from (default: those before the
    /// scored frames).
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub speed_frames: Option<(usize, usize)>,
    /// Every set runs with the evaluated set's own speed model (e.g. a track fit's, learnt from
    /// its training tracks) instead of one learnt from --speed-frames.
    #[arg(long)]
    pub own_speed: bool,
    /// Horizons (s), comma-separated.
    #[arg(long, value_name = "S,…", value_delimiter = ',', default_values_t = TrackEvalConfig::default().horizons)]
    pub horizons: Vec<f64>,
    /// Rollouts, comma-separated.
    #[arg(long, value_name = "R,…", value_delimiter = ',', value_parser = choice::<Rollout>(ROLLOUTS), default_values_t = TrackEvalConfig::default().rollouts)]
    pub rollouts: Vec<Rollout>,
    /// Seeds per set (each fixes every window's speed noise for all sets).
    #[arg(long, value_name = "K", default_value_t = TrackEvalConfig::default().seeds)]
    pub seeds: usize,
    /// Seconds between window starts (0: every frame).
    #[arg(long, value_name = "S", default_value_t = TrackEvalConfig::default().stride)]
    pub stride: f64,
    /// Frames an animal must be tracked up to a window's start to be scored (≥ 2).
    #[arg(long, value_name = "N", default_value_t = TrackEvalConfig::default().observe)]
    pub observe: usize,
    /// Blocks of consecutive windows for the verdicts over time.
    #[arg(long, value_name = "N", default_value_t = TrackEvalConfig::default().blocks)]
    pub blocks: usize,
    /// Length (s) of the free runs compared with the tracks' distributions (0: none).
    #[arg(long, value_name = "S", default_value_t = TrackEvalConfig::default().free_run)]
    pub free_run: f64,
    /// σ (cells) of the smoothing of the clip's momentum into the leaders' guidance.
    #[arg(long, value_name = "S", default_value_t = TrackEvalConfig::default().guidance_scale, allow_hyphen_values = true)]
    pub guidance_scale: f64,
    /// Whether tracked animals may lead (§5.1), the same for every set.
    #[arg(long, value_parser = choice::<Leaders>(LEADERS), default_value_t = TrackEvalConfig::default().leaders)]
    pub leaders: Leaders,
    /// The displacement errors' speeds: eq. 6 with its noise or without it (a point forecast).
    #[arg(long, value_parser = choice::<Speeds>(&SPEEDS[1..]), default_value_t = TrackEvalConfig::default().speeds)]
    pub speeds: Speeds,
    #[arg(long, value_parser = choice::<Precision>(PRECISIONS), default_value_t = Precision::F32)]
    pub precision: Precision,
    /// Output report folder.
    #[arg(long, value_name = "DIR/")]
    pub out: OutDir,
}

pub fn exec(a: ValidateTracksArgs) -> Result<()> {
    for (flag, r) in [("--frames", a.frames), ("--speed-frames", a.speed_frames)] {
        if let Some((x, y)) = r {
            if x >= y {
                return Err(crate::error::Error::invalid(format!(
                    "{flag}: {x}..{y} holds no frame"
                )));
            }
        }
    }
    let mut params: Vec<std::path::PathBuf> = vec![a.params.into()];
    params.extend(a.baseline.into_iter().map(Into::into));
    let job = TrackEvalJob {
        inputs: a.inputs.into_iter().map(Into::into).collect(),
        tracks: a.tracks.into_iter().map(Into::into).collect(),
        params,
        builtin: !a.no_builtin,
        split: a.split,
        frames: a.frames.map(|(x, y)| x..y),
        speed_frames: a.speed_frames.map(|(x, y)| x..y),
        own_speed: a.own_speed,
        config: TrackEvalConfig {
            horizons: a.horizons,
            rollouts: a.rollouts,
            seeds: a.seeds,
            stride: a.stride,
            observe: a.observe,
            blocks: a.blocks,
            free_run: a.free_run,
            guidance_scale: a.guidance_scale,
            leaders: a.leaders,
            speeds: a.speeds,
            precision: a.precision,
            ..TrackEvalConfig::default()
        },
        out: a.out.into(),
    };
    let report = run(&job, &mut Bars::default()).map_err(|e| {
        with_flags(
            e,
            &[
                ("inputs", "CLIP/"),
                ("params", "--params"),
                ("horizons", "--horizons"),
                ("stride", "--stride"),
                ("blocks", "--blocks"),
                ("free_run", "--free-run"),
                ("seeds", "--seeds"),
                ("observe", "--observe"),
                ("guidance_scale", "--guidance-scale"),
                ("speeds", "--speeds"),
            ],
        )
    })?;
    print!("{report}");
    println!("wrote {}", job.out.display());
    Ok(())
}
