//! Held-out validation (paper §7.1.2, DESIGN §7): start a herd from the fields of the first
//! held-out frame, simulate with the fitted (and baseline) parameters, and compare with the clip
//! frame by frame — density and velocity errors on a coarse grid, polarization (eq. 12), angular
//! momentum (eq. 13, about the herd centroid and the frame centre) and the aspect ratio of the
//! motion-aligned bounding box — as the mean and STD of each measure and of its error, averaged
//! over seeds (the paper's Tables 1–5).

use crate::backend::{device, Compute, Precision};
use crate::data::agents::AgentRow;
use crate::data::boundary::Gates;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::anchors::Anchors;
use crate::herd::boundary::{BoundaryChoice, Crossings};
use crate::herd::eval::run_from;
use crate::herd::guidance::guidance_fields;
use crate::herd::params::Params;
use crate::herd::start::Settle;
use crate::measure::fields::{cell_errors, coarse_cells, emergent, smooth_velocity, Emergent};
use crate::measure::rasterise;
use crate::progress::Proceed;
use serde::Serialize;

mod held_out;
pub mod paired;
mod population;
pub mod reference;
mod report;
pub mod zone_report;
pub mod zones;

pub use held_out::HeldOut;
pub use population::{BoundaryReport, Population};
pub use reference::Measures;
pub use report::{markdown, run, ValidateJob};

/// The measures compared, in report order.
pub const MEASURES: [&str; 6] = [
    "density_error",
    "velocity_error",
    "polarization",
    "angular_momentum_centroid",
    "angular_momentum_frame_centre",
    "aspect_ratio",
];

/// A run of the model over frames `range` of a clip from the first frame's fields: the agents of
/// every frame and their rasterisation on the clip's grid.
pub struct SimRun {
    pub frames: Vec<Vec<AgentRow>>,
    pub fields: ClipFields,
    /// What crossed the clip's open boundary during the run.
    pub crossings: Crossings,
}

/// Simulates `range` of the clip with `params` and seed `seed` (leaders follow `guidance`, the
/// clip's velocity field of every frame; no population control). The herd starts from the fields
/// of frame `range.start − warmup` (settled by `settle`), or from the animals `tracked` in it
/// (`validate --tracks`; each horizon piece likewise), and runs through the `warmup` frames before
/// `range` unrecorded, so that it reaches `range.start` in an arrangement of its own making rather
/// than the one sampled from fields (RESULTS.md §1, held-out validation); the returned frames and
/// fields start at `range.start`.
#[allow(clippy::too_many_arguments)]
pub fn simulate_clip(
    clip: &ClipFields,
    params: &Params,
    range: std::ops::Range<usize>,
    seed: u64,
    cfg: &ValidateConfig,
    tracked: Option<&Anchors>,
    gates: &Gates,
    guidance: &[crate::herd::sim::Guidance],
    device: &burn::tensor::Device,
) -> Result<SimRun> {
    let mut crossings = Crossings::default();
    // The agents of every frame of `piece`, the herd started from the fields of frame
    // `piece.start − warmup` (or from the animals `tracked` in it) and run through the warm-up
    // unrecorded.
    let run_piece = |piece: std::ops::Range<usize>, seed: u64| -> Result<Vec<Vec<AgentRow>>> {
        let first = piece.start - cfg.warmup.min(piece.start);
        let mut frames = Vec::with_capacity(piece.len());
        let last = piece.end.saturating_sub(1);
        let (rows, crossed) = run_from(
            clip,
            params,
            None,
            tracked.and_then(|a| a.at(first)),
            gates,
            (first, last),
            seed,
            &cfg.settle,
            guidance,
            device,
            |f, state, ids| {
                if f >= piece.start {
                    frames.push(state.rows(ids)?);
                }
                Ok(())
            },
        )?;
        crossings.add(&crossed);
        if first == piece.start {
            frames.insert(0, rows);
        }
        Ok(frames)
    };
    let mut frames = Vec::with_capacity(range.len());
    let mut run_piece = run_piece;
    // With a horizon, the herd is drawn afresh from the clip every `horizon` frames (each piece
    // with its own seed derived from `seed`, the same for every parameter set).
    let step = if cfg.horizon == 0 {
        range.len()
    } else {
        cfg.horizon
    };
    let mut a = range.start;
    while a < range.end {
        let b = (a + step).min(range.end);
        let piece_seed = seed + (((a - range.start) / step) as u64) * 1_000_003;
        frames.extend(run_piece(a..b, piece_seed)?);
        a = b;
    }
    let mut fields = rasterise(
        &frames,
        clip.grid(),
        clip.meta.fps,
        clip.obstacles.clone(),
        serde_json::json!({"source": "validate simulation", "seed": seed}),
    )?;
    smooth_velocity(&mut fields, clip.meta.velocity_window());
    Ok(SimRun {
        frames,
        fields,
        crossings,
    })
}

/// Mean and standard deviation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Stat {
    pub mean: f64,
    pub std: f64,
}

pub(crate) fn stat(v: &[f64]) -> Stat {
    let v: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if v.is_empty() {
        return Stat {
            mean: f64::NAN,
            std: f64::NAN,
        };
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    let s = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
    Stat { mean: m, std: s }
}

/// One measure for one parameter set: the video's value, the simulation's value and the
/// per-frame absolute error, each as mean ± STD over frames (averaged over seeds).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeasureRow {
    pub measure: String,
    pub video: Option<Stat>,
    pub simulation: Option<Stat>,
    pub error: Stat,
}

/// The validation of one parameter set.
#[derive(Clone, Debug, Serialize)]
pub struct SetReport {
    pub name: String,
    pub params: [f64; 12],
    pub rows: Vec<MeasureRow>,
    /// Per frame, seed-averaged: [density error, velocity error, polarization, ang. momentum
    /// centroid, ang. momentum frame centre, aspect ratio] of the simulation.
    pub per_frame: Vec<[f64; 6]>,
    /// Mean |ρ' − ρ| (agents) per coarse cell over frames and seeds (of the seeds' mean
    /// prediction with `ensemble_mean`), row 0 at the bottom.
    pub error_map: Vec<Vec<f64>>,
    /// The set's identifiability estimate from its fit (issue #15 item 2), when it has one.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<crate::herd::uncertainty::Uncertainty>,
    /// Per seed, the mean over the held-out frames of each measure's error (the order of
    /// [`MEASURES`]); empty for the seeds' mean prediction. The row errors' means are their
    /// average when every frame's value is finite.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub seed_errors: Vec<[f64; 6]>,
    /// Through an open boundary: what entered and left, and the count in the view frame by
    /// frame. Absent for a closed clip.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub population: Option<Population>,
    /// The reference implementation's measures (`measures: reference`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference: Option<reference::RefReport>,
}

impl SetReport {
    /// The mean error of a measure.
    pub fn error(&self, measure: &str) -> f64 {
        self.rows
            .iter()
            .find(|r| r.measure == measure)
            .map_or(f64::NAN, |r| r.error.mean)
    }
}

/// Schema tag of validation reports (`report.json`).
pub const VALIDATION_SCHEMA: &str = "herdfit.validation/1";

fn is_auto(b: &BoundaryChoice) -> bool {
    *b == BoundaryChoice::Auto
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct Report {
    #[serde(flatten)]
    pub run: HeldOut,
    /// Whether the seeds' mean prediction was compared ([`ValidateConfig::ensemble_mean`]).
    pub ensemble_mean: bool,
    /// The video's per-frame measures: [polarization, ang. momentum centroid, frame centre,
    /// aspect ratio].
    pub video_per_frame: Vec<[f64; 4]>,
    /// The clip's open boundary, when it has one: its entry and exit gates and the video's count
    /// at each held-out frame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub boundary: Option<BoundaryReport>,
    pub sets: Vec<SetReport>,
    /// The first set against each other set, seed by seed ([`paired`]); empty with one set or
    /// for the seeds' mean prediction.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub paired: Vec<paired::Paired>,
}

/// Settings of a validation.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidateConfig {
    /// Fraction of the clip before the held-out part.
    pub split: f64,
    /// Coarse grid (cells per side) of the density and velocity errors (the report's `grid`).
    pub coarse_grid: usize,
    /// Simulations per parameter set.
    pub seeds: usize,
    /// How the starting herd is settled.
    pub settle: Settle,
    /// Frames before the held-out part that the herd is simulated through first (0: it starts
    /// from the fields of the first held-out frame).
    pub warmup: usize,
    /// σ (cells) of the smoothing that turns the clip's momentum into leader guidance
    /// ([`crate::herd::guidance::guidance_field`]).
    #[serde(with = "crate::limits::infinite_ok")]
    pub guidance_scale: f64,
    /// Compare the seeds' mean prediction (coarse counts and momenta, each measure averaged over
    /// the seeds frame by frame) with the clip, instead of averaging each seed's own errors. A
    /// stochastic herd's best prediction is its expectation; per-seed errors also charge it for
    /// its own run-to-run spread, which favours sets that make the herd less variable.
    pub ensemble_mean: bool,
    /// Frames after which the herd is drawn afresh from the clip's fields (0: never, the paper's
    /// §7.1.2 protocol of one run through the whole held-out part). A short horizon scores how
    /// the set predicts the next frames from where the animals are, which a free run over a
    /// sparse clip stops doing once its herd no longer overlaps the clip's (RESULTS.md §6).
    pub horizon: usize,
    /// Tracked animals of the clip (`validate --tracks`, as `fit --tracks`): every run (every
    /// piece, with a horizon) starts from the animals tracked at its first frame. Not written
    /// when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracks: Option<std::path::PathBuf>,
    /// The clip's open boundary ([`crate::herd::boundary`]): `auto` (the gates the clip's flux
    /// shows; closed when nothing crosses its edge), `closed`, or a `herdfit.boundary/1` file.
    /// Not written when `auto`.
    #[serde(default, skip_serializing_if = "is_auto")]
    pub boundary: BoundaryChoice,
    /// The held-out frames `[a, b)` (`--frames a..b`), instead of `split` to the end: e.g. the
    /// reference's logging protocol, 100 frames from the clip's start. Not written when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames: Option<[usize; 2]>,
    /// Which measures to report: herdfit's own, or also the reference implementation's
    /// ([`reference`](mod@reference)). Not written when herdfit's own.
    #[serde(default, skip_serializing_if = "is_herdfit")]
    pub measures: Measures,
    /// Where the model's tensors live (`--device`). Not written when `cpu`.
    #[serde(default, skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
}

fn is_herdfit(m: &Measures) -> bool {
    *m == Measures::Herdfit
}

impl Default for ValidateConfig {
    fn default() -> Self {
        ValidateConfig {
            split: 0.5,
            coarse_grid: 10,
            seeds: 3,
            settle: Settle::default(),
            warmup: 0,
            guidance_scale: crate::herd::guidance::GUIDANCE_SCALE,
            ensemble_mean: false,
            horizon: 0,
            tracks: None,
            boundary: BoundaryChoice::Auto,
            frames: None,
            measures: Measures::Herdfit,
            device: Compute::Cpu,
        }
    }
}

impl ValidateConfig {
    /// The animals tracked in `clip` ([`Self::tracks`]) from the first frame a run starts at,
    /// when the validation starts from tracks; errors name the tracks file.
    pub fn anchors(&self, clip: &ClipFields) -> Result<Option<Anchors>> {
        let held = self.held_out_start(clip.frames());
        let first = held - self.warmup.min(held);
        self.tracks
            .as_ref()
            .map(|p| Anchors::load(p, clip, first..clip.frames()))
            .transpose()
    }

    /// The first held-out frame of a clip of `frames` frames: the start of [`Self::frames`]
    /// when given, else ⌊frames · split⌋.
    pub fn held_out_start(&self, frames: usize) -> usize {
        match self.frames {
            Some([a, _]) => a,
            None => ((frames as f64) * self.split).floor() as usize,
        }
    }

    /// The held-out frames `(start, end)` of a clip of `frames` frames: [`Self::frames`] when
    /// given (checked against the clip), else from ⌊frames · split⌋ to the end.
    pub fn held_out(&self, frames: usize) -> Result<(usize, usize)> {
        match self.frames {
            Some([a, b]) if a < b && b <= frames => Ok((a, b)),
            Some([a, b]) => Err(Error::config(
                "frames",
                format!("{a}..{b} is not a range of frames inside the clip's 0..{frames}"),
            )),
            None => Ok((self.held_out_start(frames), frames)),
        }
    }

    /// The held-out frames `(start, end)` of `clip` ([`Self::held_out`]), checked: not a still,
    /// at least 2 frames, the warm-up inside the clip.
    pub fn held_out_checked(&self, clip: &ClipFields) -> Result<(usize, usize)> {
        let cfg = self;
        if clip.frames() == 1 {
            return Err(Error::invalid(
                "the clip is a still (one frame): it has no held-out part; `herdfit fit` scores a still \
                 itself (its parameter set's provenance.evaluation.still)",
            ));
        }
        // `nf`: the end of the held-out part (the clip's end unless `frames` says otherwise).
        let (start, nf) = cfg.held_out(clip.frames())?;
        if nf - start < 2 {
            return Err(Error::invalid(format!(
                "the held-out part {start}..{nf} has fewer than 2 frames"
            )));
        }
        if cfg.warmup > start {
            return Err(Error::config(
                "warmup",
                format!(
                    "{} frames reach before the clip: the held-out part starts at frame {start}",
                    cfg.warmup
                ),
            ));
        }
        Ok((start, nf))
    }

    /// Checks the ranges; errors name the key.
    pub fn check(&self) -> Result<()> {
        if !(self.split.is_finite() && (0.0..1.0).contains(&self.split)) {
            return Err(Error::config(
                "split",
                format!("{} must be in [0, 1)", self.split),
            ));
        }
        crate::error::check_counts(&[("coarse_grid", self.coarse_grid), ("seeds", self.seeds)])?;
        // Up front (issue #47: --seeds 10^9 ran until killed, --coarse-grid 10^9 was accepted).
        crate::limits::check_grid("coarse_grid", self.coarse_grid, self.coarse_grid)?;
        crate::limits::check_count("seeds", self.seeds, crate::limits::MAX_RUNS)?;
        crate::limits::check_count("warmup", self.warmup, crate::limits::MAX_STEPS)?;
        crate::limits::check_count("horizon", self.horizon, crate::limits::MAX_STEPS)?;
        crate::herd::guidance::check_guidance_scale(self.guidance_scale)?;
        if self.horizon == 1 {
            return Err(Error::config(
                "horizon",
                "1 frame holds no motion: 0 (one run) or at least 2",
            ));
        }
        self.settle.check()
    }
}

/// One row per measure of [`MEASURES`]: the video's and the simulation's values (emergent
/// measures only) and the errors, each as mean ± STD over frames and seeds.
fn measure_rows(video: &[Emergent], sims: &[Vec<f64>], errs: &[Vec<f64>]) -> Vec<MeasureRow> {
    MEASURES
        .iter()
        .enumerate()
        .map(|(m, name)| MeasureRow {
            measure: name.to_string(),
            video: (m >= 2).then(|| {
                let v: Vec<f64> = video.iter().map(|e| e.values()[m - 2]).collect();
                stat(&v)
            }),
            simulation: (m >= 2).then(|| stat(&sims[m])),
            error: stat(&errs[m]),
        })
        .collect()
}

/// Validates parameter sets on the held-out part `[split·F, F)` of a clip.
pub fn validate<R: Proceed>(
    clip: &ClipFields,
    clip_name: &str,
    sets: &[(String, Params)],
    cfg: &ValidateConfig,
    mut progress: impl FnMut() -> R,
) -> Result<(Report, Vec<Vec<SimRun>>)> {
    cfg.check()?;
    let (split, grid, seeds) = (cfg.split, cfg.coarse_grid, cfg.seeds);
    // `nf`: the end of the held-out part (the clip's end unless `frames` says otherwise).
    let (start, nf) = cfg.held_out_checked(clip)?;
    let anchors = cfg.anchors(clip)?;
    let gates = cfg.boundary.gates(clip)?;
    let device = device(cfg.device, Precision::F32)?;
    // The leaders' guidance of every frame, the same for every set and seed.
    let guidance = guidance_fields(clip, cfg.guidance_scale);
    let video: Vec<Emergent> = (start..nf).map(|f| emergent(clip, f)).collect();
    let clip_cells: Vec<Vec<[f64; 3]>> = (start..nf).map(|f| coarse_cells(clip, f, grid)).collect();
    let mut reports = Vec::new();
    let mut runs_all = Vec::new();
    let (kx, ky) = (grid.min(clip.meta.nx), grid.min(clip.meta.ny));
    for (name, params) in sets {
        params.validate()?;
        let mut per_frame = vec![[0.0f64; 6]; nf - start];
        let mut errs: Vec<Vec<f64>> = vec![Vec::new(); 6];
        let mut sims: Vec<Vec<f64>> = vec![Vec::new(); 6];
        let mut map = vec![vec![0.0f64; kx]; ky];
        let mut runs = Vec::new();
        // One frame's simulated values (weight w: 1/seeds per run, or 1 for the ensemble mean):
        // errors against the video, per-frame means and the coarse density error map.
        let mut record = |k: usize, sim_vals: [f64; 6], cells: &[[f64; 3]], w: f64| {
            let vid = video[k].values();
            let vid_vals = [0.0, 0.0, vid[0], vid[1], vid[2], vid[3]];
            for m in 0..6 {
                let err = if m < 2 {
                    sim_vals[m]
                } else {
                    (sim_vals[m] - vid_vals[m]).abs()
                };
                errs[m].push(err);
                sims[m].push(sim_vals[m]);
                per_frame[k][m] += w * sim_vals[m];
            }
            for (c, (s, v)) in cells.iter().zip(&clip_cells[k]).enumerate() {
                map[c / kx][c % kx] += w * (s[0] - v[0]).abs() / (nf - start) as f64;
            }
        };
        // Seed-averaged coarse cells and measures (the ensemble's prediction of each frame),
        // accumulated only with `ensemble_mean`.
        let mut mean_cells = vec![vec![[0.0f64; 3]; kx * ky]; nf - start];
        let mut mean_vals = vec![[0.0f64; 4]; nf - start];
        let w = 1.0 / seeds as f64;
        let mut population = Population::new(nf - start);
        for seed in 0..seeds {
            let run = simulate_clip(
                clip,
                params,
                start..nf,
                seed as u64,
                cfg,
                anchors.as_ref(),
                &gates,
                &guidance,
                &device,
            )?;
            for k in 0..nf - start {
                // The simulation's fields are indexed from the first held-out frame.
                let cells = coarse_cells(&run.fields, k, grid);
                let vals = emergent(&run.fields, k).values();
                if cfg.ensemble_mean {
                    for (m, c) in mean_cells[k].iter_mut().zip(&cells) {
                        for j in 0..3 {
                            m[j] += w * c[j];
                        }
                    }
                    for j in 0..4 {
                        mean_vals[k][j] += w * vals[j];
                    }
                } else {
                    let (de, ve) = cell_errors(&clip_cells[k], &cells);
                    record(k, [de, ve, vals[0], vals[1], vals[2], vals[3]], &cells, w);
                }
            }
            population.add(&run, w);
            runs.push(run);
            progress().proceed()?;
        }
        if cfg.ensemble_mean {
            for k in 0..nf - start {
                let (de, ve) = cell_errors(&clip_cells[k], &mean_cells[k]);
                let v = mean_vals[k];
                record(k, [de, ve, v[0], v[1], v[2], v[3]], &mean_cells[k], 1.0);
            }
        }
        let rows = measure_rows(&video, &sims, &errs);
        reports.push(SetReport {
            name: name.clone(),
            params: params.to_vec(),
            rows,
            per_frame,
            error_map: map,
            uncertainty: params.uncertainty.clone(),
            seed_errors: if cfg.ensemble_mean {
                Vec::new()
            } else {
                paired::seed_means(&errs, seeds, nf - start)
            },
            population: gates.is_open().then_some(population),
            reference: (cfg.measures == Measures::Reference)
                .then(|| reference::reference_of(clip, start, &runs)),
        });
        runs_all.push(runs);
    }
    Ok((
        Report {
            run: HeldOut {
                schema: VALIDATION_SCHEMA.into(),
                clip: clip_name.to_string(),
                frames: [start, nf],
                split,
                grid,
                seeds,
                horizon: cfg.horizon,
                tracks: cfg.tracks.as_ref().map(|t| t.display().to_string()),
                device: cfg.device,
            },
            ensemble_mean: cfg.ensemble_mean,
            video_per_frame: video.iter().map(Emergent::values).collect(),
            boundary: gates.is_open().then(|| BoundaryReport {
                video_count: (start..nf).map(|f| clip.count(f)).collect(),
                gates: gates.clone(),
            }),
            paired: paired::comparisons(&reports),
            sets: reports,
        },
        runs_all,
    ))
}
