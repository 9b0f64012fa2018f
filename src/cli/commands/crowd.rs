//! `herdfit crowd …`: learn a crowd model from tracks, simulate it, evaluate it on ETH/UCY,
//! compare crowds. Each verb: flags → config → one library call → print.

use super::crowd_flags::{flagged, read_json, write_json, LearnFlags};
use crate::cli::paths::{InDir, InFile, OutFile, OutTracks};
use crate::crowd::eval::{evaluate, EvalConfig};
use crate::crowd::features::Scene;
use crate::crowd::holdout::{holdout, HoldoutConfig};
use crate::crowd::layout::Layout;
use crate::crowd::measure::compare;
use crate::crowd::model::{learn, read_tracks, CrowdModel, LearnConfig};
use crate::crowd::sim::{
    entries_from_layout, entries_from_tracks, simulate, typical_speed, SimConfig,
};
use crate::crowd::{render, synth};
use crate::error::{Error, Result};
use clap::{Args, Subcommand};
use std::path::{Path, PathBuf};

/// Walking groups among real tracks' entries ([`SimConfig::together`]).
#[derive(Args, Debug)]
pub struct TogetherFlags {
    /// Walking groups: entries that appear and are last seen within this distance (units) and
    /// `--together-seconds` of each other walk together, the others taking the first one's steps
    /// (0: off).
    #[arg(long, value_name = "M", default_value_t = SimConfig::default().together)]
    pub together: f64,
    /// Seconds apart that walking-group members may enter and leave.
    #[arg(long, value_name = "S", default_value_t = SimConfig::default().together_seconds)]
    pub together_seconds: f64,
}

/// The crowd verbs.
#[derive(Subcommand, Debug)]
pub enum CrowdCommand {
    /// Learn a crowd model (herdfit.crowd-model/1) from tracks: herdfit.tracks/1 CSV or ETH/UCY .txt.
    Learn(LearnArgs),
    /// Simulate a learnt crowd in a layout (its spawns) or entering as the agents of real tracks did.
    Simulate(SimulateArgs),
    /// ETH/UCY leave-one-scene-out forecasting (observe 8, predict 12) beside constant velocity.
    Evaluate(EvaluateArgs),
    /// Compare two crowds: speed, nearest-neighbour, turning and polarization distributions
    /// (Wasserstein distances) and density maps.
    Compare(CompareArgs),
    /// Write a synthetic social-force corridor crowd (tracks CSV) to learn from.
    Synth(SynthArgs),
    /// Split real tracks in time, learn from the first part, simulate the second part's entries
    /// and compare (Wasserstein distances against those between the two real parts).
    Holdout(HoldoutArgs),
}

/// Named learn configurations.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    /// The paper's Table 1 locomotion and chat rows, eq. 3's regression.
    Paper,
    /// Imitation of real pedestrians (`LearnConfig::pedestrians`).
    Pedestrians,
}

impl Preset {
    fn config(self) -> LearnConfig {
        match self {
            Preset::Paper => LearnConfig::default(),
            Preset::Pedestrians => LearnConfig::pedestrians(),
        }
    }
}

#[derive(Args, Debug)]
pub struct LearnArgs {
    /// Training tracks (several allowed, same units and frame rate).
    #[arg(value_name = "TRACKS", num_args = 1.., required = true)]
    pub inputs: Vec<InFile>,
    /// Starting configuration (--config and the flags override it).
    #[arg(long, value_enum, default_value = "paper")]
    pub preset: Preset,
    #[command(flatten)]
    pub flags: LearnFlags,
    /// Output model.
    #[arg(long, value_name = "MODEL.json")]
    pub out: OutFile,
}

#[derive(Args, Debug)]
pub struct SimulateArgs {
    #[arg(value_name = "MODEL.json")]
    pub model: InFile,
    /// Layout with walls, obstacles, pivots, regions and spawns.
    #[arg(long, value_name = "LAYOUT.json")]
    pub layout: Option<InFile>,
    /// Agents enter where and when those of these tracks did, heading to where they left, and
    /// leave when they did.
    #[arg(long, value_name = "TRACKS", required_unless_present = "layout")]
    pub entries: Option<InFile>,
    /// Steps (0: the layout's duration or until the last entry is done).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub steps: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// With --entries: agents keep their own past direction instead of heading to where the real
    /// ones left, and stay until the end (--steps; default the tracks' length).
    #[arg(long, requires = "entries")]
    pub no_goals: bool,
    /// With --entries: agents leave on reaching their goals (or when their time is up) instead
    /// of when the real ones left.
    #[arg(long, requires = "entries")]
    pub leave_at_goal: bool,
    /// Every agent uses locomotion (no groups or lines).
    #[arg(long)]
    pub no_behaviours: bool,
    /// An agent with a goal never walks more than this many degrees away from the direction to
    /// it (its learnt step is turned to the edge of the cone; 180: off).
    #[arg(long, value_name = "DEG", default_value_t = SimConfig::default().goal_cone_deg)]
    pub goal_cone: f64,
    /// Hard minimum distance between agents after each step (units; 0: off).
    #[arg(long, value_name = "M", default_value_t = SimConfig::default().min_distance)]
    pub min_distance: f64,
    #[command(flatten)]
    pub together: TogetherFlags,
    /// Top-view PNG of the middle frame.
    #[arg(long, value_name = "OUT.png")]
    pub png: Option<OutFile>,
    /// Top-view MJPG AVI (needs the `video` feature).
    #[arg(long, value_name = "OUT.avi")]
    pub video: Option<OutFile>,
    /// Comparison with the --entries tracks (JSON).
    #[arg(long, value_name = "OUT.json", requires = "entries")]
    pub compare: Option<OutFile>,
    /// Output tracks (herdfit.tracks/1 CSV + sidecar).
    #[arg(long, value_name = "TRACKS.csv")]
    pub out: OutTracks,
}

#[derive(Args, Debug)]
pub struct EvaluateArgs {
    /// Folder of the ETH/UCY text files (default: $HERDFIT_SHARED_DATA/pedestrians/eth-ucy or
    /// ../shared/data/pedestrians/eth-ucy).
    #[arg(long, value_name = "DIR")]
    pub data: Option<InDir>,
    /// Test scene (repeat; default all five).
    #[arg(long, value_name = "NAME")]
    pub scene: Vec<String>,
    #[command(flatten)]
    pub flags: LearnFlags,
    /// Sample a cluster with eq. 2's probabilities instead of taking the most probable.
    #[arg(long)]
    pub sample_clusters: bool,
    /// Attraction range (standard deviations; 0: off).
    #[arg(long, value_name = "C")]
    pub attraction: Option<f64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Hyper-parameter candidates chosen inside each test scene's training scenes (TuningConfig
    /// JSON file: smoothing, bandwidth_scale, formation, inertia lists, frame_stride).
    #[arg(long, value_name = "TUNING.json")]
    pub tuning: Option<InFile>,
    /// Hard minimum distance (m) between rolled-out pedestrians (0: off).
    #[arg(long, value_name = "M")]
    pub min_distance: Option<f64>,
    /// Report (herdfit.crowd-eval/1 JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<OutFile>,
}

#[derive(Args, Debug)]
pub struct CompareArgs {
    #[arg(value_name = "A")]
    pub a: InFile,
    #[arg(value_name = "B")]
    pub b: InFile,
    /// Density-map cell (tracks' unit).
    #[arg(long, value_name = "C", default_value_t = 1.0)]
    pub cell: f64,
    /// Frame rate of ETH/UCY .txt inputs.
    #[arg(long, value_name = "FPS", default_value_t = 2.5)]
    pub eth_fps: f64,
    /// Report (herdfit.crowd-compare/1 JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<OutFile>,
}

#[derive(Args, Debug)]
pub struct HoldoutArgs {
    /// Tracks: herdfit.tracks/1 CSV or ETH/UCY .txt.
    #[arg(value_name = "TRACKS")]
    pub tracks: InFile,
    /// Walls and obstacles the simulated agents keep to (its spawns are not used).
    #[arg(long, value_name = "LAYOUT.json")]
    pub layout: Option<InFile>,
    /// Starting learn configuration (--config and the flags override it).
    #[arg(long, value_enum, default_value = "pedestrians")]
    pub preset: Preset,
    #[command(flatten)]
    pub flags: LearnFlags,
    /// Fraction of the agent-frames learnt from (the first part in time).
    #[arg(long, value_name = "F", default_value_t = 0.5)]
    pub split: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Agents leave on reaching their goals instead of when the real ones left.
    #[arg(long)]
    pub leave_at_goal: bool,
    /// Goal cone of the simulation (degrees; see `crowd simulate --goal-cone`).
    #[arg(long, value_name = "DEG", default_value_t = SimConfig::default().goal_cone_deg)]
    pub goal_cone: f64,
    /// Hard minimum distance between simulated agents (units; 0: off).
    #[arg(long, value_name = "M", default_value_t = SimConfig::default().min_distance)]
    pub min_distance: f64,
    #[command(flatten)]
    pub together: TogetherFlags,
    /// The simulated second part (herdfit.tracks/1 CSV + sidecar).
    #[arg(long, value_name = "SIM.csv")]
    pub out: Option<OutTracks>,
    /// Report (herdfit.crowd-holdout/1 JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<OutFile>,
}

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Seconds simulated.
    #[arg(long, value_name = "S")]
    pub duration: Option<f64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, value_name = "TRACKS.csv")]
    pub out: OutTracks,
}

/// Runs a crowd verb.
pub fn run(c: CrowdCommand) -> Result<()> {
    match c {
        CrowdCommand::Learn(a) => learn_cmd(a),
        CrowdCommand::Simulate(a) => simulate_cmd(a),
        CrowdCommand::Evaluate(a) => evaluate_cmd(a),
        CrowdCommand::Compare(a) => compare_cmd(a),
        CrowdCommand::Synth(a) => synth_cmd(a),
        CrowdCommand::Holdout(a) => holdout_cmd(a),
    }
}

fn learn_cmd(a: LearnArgs) -> Result<()> {
    let cfg = a.flags.config(a.preset.config())?;
    cfg.check().map_err(|e| a.flags.name(e))?;
    crate::data::atomic::check_writable(&a.out)?;
    let inputs = a
        .inputs
        .iter()
        .map(|p| read_tracks(p, cfg.eth_fps))
        .collect::<Result<Vec<_>>>()?;
    let mut bars = crate::cli::Bars::default();
    let m = learn(&inputs, &cfg, &mut bars).map_err(|e| match a.inputs.as_slice() {
        [one] => e.in_file(one),
        _ => e,
    })?;
    m.save(&a.out)?;
    let names: Vec<String> = m
        .behaviours
        .iter()
        .map(|b| format!("{} {}", b.name, b.model.samples.len()))
        .collect();
    println!(
        "crowd learn: {} samples ({}), PCA {} → {}; mean group {:.2}, interpersonal {:.2} {}; wrote {}",
        m.samples(),
        names.join(", "),
        m.behaviours[0].pca.input(),
        m.behaviours[0].pca.dims(),
        m.fsm.group_size,
        m.fsm.interpersonal,
        m.units.as_str(),
        a.out.display()
    );
    Ok(())
}

fn simulate_cmd(a: SimulateArgs) -> Result<()> {
    let model = CrowdModel::load(&a.model)?;
    let layout = a.layout.as_deref().map(Layout::load).transpose()?;
    let real = match &a.entries {
        Some(p) => {
            let t = read_tracks(p, 1.0 / model.dt)?;
            Some((Scene::from_tracks(&t, 0.0).map_err(|e| e.in_file(p))?, t))
        }
        None => None,
    };
    let mut steps = a.steps;
    let entries = match (&real, &layout) {
        (Some((s, _)), _) => {
            let mut e = entries_from_tracks(s);
            if a.no_goals || a.leave_at_goal {
                e.iter_mut().for_each(|e| e.leave = None);
            }
            if a.no_goals {
                e.iter_mut().for_each(|e| e.goal = None);
                if steps == 0 {
                    steps = s.frames().saturating_sub(1).max(1);
                }
            }
            e
        }
        (None, Some(l)) => entries_from_layout(l, model.dt, typical_speed(&model), a.seed),
        (None, None) => unreachable!("clap requires one"),
    };
    let cfg = SimConfig {
        steps,
        seed: a.seed,
        behaviours: !a.no_behaviours,
        goal_cone_deg: a.goal_cone,
        min_distance: a.min_distance,
        together: a.together.together,
        together_seconds: a.together.together_seconds,
        ..SimConfig::default()
    };
    let mut bars = crate::cli::Bars::default();
    let t0 = std::time::Instant::now();
    let run = simulate(&model, layout.as_ref(), &entries, &cfg, &mut bars).map_err(|e| {
        let from_layout = a.steps == 0 && a.layout.is_some();
        let e = flagged(e, &|k| k != "steps" || !from_layout, None);
        match (&a.layout, e) {
            // Steps drawn from the layout's duration: the layout is to blame.
            (Some(l), Error::Config { file: None, err }) if from_layout => {
                Error::file(l, format!("duration: {}", err.msg))
            }
            (_, e) => e,
        }
    })?;
    let secs = t0.elapsed().as_secs_f64();
    if let Some(p) = &a.png {
        let mid = run.tracks.rows.last().map_or(0, |r| r.frame) / 2;
        render::top_view_png(
            p,
            "herdfit crowd simulate",
            &run.tracks,
            real.as_ref().map(|r| &r.1),
            layout.as_ref(),
            mid,
            10,
        )?;
    }
    if let Some(p) = &a.video {
        #[cfg(feature = "video")]
        render::top_view_avi(p, &run.tracks, layout.as_ref(), 24.0)?;
        #[cfg(not(feature = "video"))]
        return Err(Error::file(p, "AVI output needs the `video` feature"));
    }
    if let (Some(p), Some((s, _))) = (&a.compare, &real) {
        let sim = Scene::from_tracks(&run.tracks, 0.0)?;
        let c = compare(
            s,
            &sim,
            "real",
            "simulated",
            model.config.features.still_speed,
            model.units.as_str(),
            1.0,
        )?;
        write_json(p, &c)?;
    }
    run.tracks.save(&a.out)?;
    println!(
        "crowd simulate: {} agents, {} agent-steps in {:.2} s ({:.0}/s); {} arrived, {} timed out, {} walking groups of {} agents, {} groups formed, {} joined a line; wrote {}",
        entries.len(),
        run.agent_steps,
        secs,
        run.agent_steps as f64 / secs.max(1e-9),
        run.arrived,
        run.timed_out,
        run.walking_groups.0,
        run.walking_groups.1,
        run.groups_formed,
        run.line_joins,
        a.out.display()
    );
    Ok(())
}

/// The ETH/UCY folder: `$HERDFIT_SHARED_DATA/pedestrians/eth-ucy`, else
/// `../shared/data/pedestrians/eth-ucy`.
pub fn default_eth_ucy() -> PathBuf {
    match std::env::var_os("HERDFIT_SHARED_DATA") {
        Some(d) => PathBuf::from(d).join("pedestrians/eth-ucy"),
        None => PathBuf::from("../shared/data/pedestrians/eth-ucy"),
    }
}

fn evaluate_cmd(a: EvaluateArgs) -> Result<()> {
    let base = EvalConfig::default();
    let mut cfg = EvalConfig {
        learn: a.flags.config(base.learn.clone())?,
        data: a.data.clone().map_or_else(default_eth_ucy, Into::into),
        scenes: a.scene.clone(),
        seed: a.seed,
        ..base
    };
    if a.sample_clusters {
        cfg.learn.action.choice = crate::crowd::action::ClusterChoice::Sample;
    }
    if let Some(c) = a.attraction {
        cfg.learn.action.attraction = c;
    }
    if let Some(p) = &a.tuning {
        cfg.tuning = read_json(p)?;
    }
    if let Some(m) = a.min_distance {
        cfg.min_distance = m;
    }
    if let Some(p) = &a.json {
        crate::data::atomic::check_writable(p)?;
    }
    let mut bars = crate::cli::Bars::default();
    let given = |k: &str| match k {
        "action.attraction" => a.attraction.is_some(),
        "min_distance" => a.min_distance.is_some(),
        k => a.flags.given(k),
    };
    let rep =
        evaluate(&cfg, &mut bars).map_err(|e| flagged(e, &given, a.flags.config.as_deref()))?;
    print!("{rep}");
    if let Some(p) = &a.json {
        write_json(p, &rep)?;
    }
    Ok(())
}

fn compare_cmd(a: CompareArgs) -> Result<()> {
    let flag = |e| flagged(e, &|_| true, None);
    crate::limits::within("cell", a.cell, 1e-9, crate::limits::MAX_COORD).map_err(flag)?;
    let (lo, hi) = crate::limits::FPS_RANGE;
    crate::limits::within("eth_fps", a.eth_fps, lo, hi).map_err(flag)?;
    let load = |p: &Path| -> Result<(Scene, String)> {
        let t = read_tracks(p, a.eth_fps)?;
        let u = t.meta.units.as_str().to_string();
        Ok((Scene::from_tracks(&t, 0.0).map_err(|e| e.in_file(p))?, u))
    };
    let ((sa, ua), (sb, ub)) = (load(&a.a)?, load(&a.b)?);
    if ua != ub {
        return Err(Error::invalid(format!(
            "{} is in {ua} but {} in {ub}",
            a.a.display(),
            a.b.display()
        )));
    }
    if let Some(p) = &a.json {
        crate::data::atomic::check_writable(p)?;
    }
    let c = compare(
        &sa,
        &sb,
        &a.a.display().to_string(),
        &a.b.display().to_string(),
        0.05,
        &ua,
        a.cell,
    )?;
    println!(
        "{:<18} {:>10} {:>10} {:>10}",
        "measure", "mean A", "mean B", "W1"
    );
    for m in &c.measures {
        println!(
            "{:<18} {:>10.4} {:>10.4} {:>10.4} {}",
            m.name, m.mean_a, m.mean_b, m.wasserstein, m.unit
        );
    }
    println!(
        "density maps ({} cells): total variation {:.4}, correlation {:.4}",
        a.cell, c.density_tv, c.density_correlation
    );
    if let Some(p) = &a.json {
        write_json(p, &c)?;
    }
    Ok(())
}

fn holdout_cmd(a: HoldoutArgs) -> Result<()> {
    let base = HoldoutConfig::default();
    let cfg = HoldoutConfig {
        learn: a.flags.config(a.preset.config())?,
        sim: SimConfig {
            seed: a.seed,
            goal_cone_deg: a.goal_cone,
            min_distance: a.min_distance,
            together: a.together.together,
            together_seconds: a.together.together_seconds,
            ..base.sim.clone()
        },
        split: a.split,
        leave_at_goal: a.leave_at_goal,
        ..base
    };
    // --split, --goal-cone and --min-distance always set their keys (they have defaults).
    let given = |k: &str| match k {
        "split" | "goal_cone" | "min_distance" | "together" | "together_seconds" => true,
        k => a.flags.given(k),
    };
    cfg.check()
        .map_err(|e| flagged(e, &given, a.flags.config.as_deref()))?;
    let layout = a.layout.as_deref().map(Layout::load).transpose()?;
    let t = read_tracks(&a.tracks, cfg.learn.eth_fps)?;
    let mut bars = crate::cli::Bars::default();
    let h = holdout(
        &t,
        layout.as_ref(),
        &cfg,
        &a.tracks.display().to_string(),
        &mut bars,
    )
    .map_err(|e| e.in_file(&a.tracks))?;
    println!("{}", h.report);
    if let Some(p) = &a.out {
        h.simulated.save(p)?;
    }
    if let Some(p) = &a.json {
        write_json(p, &h.report)?;
    }
    Ok(())
}

fn synth_cmd(a: SynthArgs) -> Result<()> {
    let mut cfg = synth::SynthConfig {
        seed: a.seed,
        ..synth::SynthConfig::default()
    };
    if let Some(d) = a.duration {
        cfg.duration = d;
    }
    let t = synth::corridor(&cfg).map_err(|e| flagged(e, &|_| true, None))?;
    t.save(&a.out)?;
    println!(
        "crowd synth: {} walkers, {} rows; wrote {}",
        t.ids().len(),
        t.rows.len(),
        a.out.display()
    );
    Ok(())
}
