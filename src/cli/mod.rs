//! The `herdfit` command line: one verb per pipeline arrow (DESIGN §1), one file per verb in
//! [`commands`]. A command parses its flags into the library's job, makes one library call and
//! prints; the library's typed errors become one-line messages in `main.rs`.

pub mod args;
pub mod commands;
pub mod numbers;
pub mod paths;
pub mod progress;

pub use progress::{progress_bar, Bars};

use crate::error::Result;
use clap::{Parser, Subcommand};
use commands::*;

/// Learn how animal groups move from video and replay that behaviour anywhere.
#[derive(Parser, Debug)]
#[command(name = "herdfit", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Simulate a herd with a parameter set and write its trajectories (CSV).
    Simulate(simulate::SimulateArgs),
    /// Check the autodiff gradient of an unrolled run against finite differences.
    Gradcheck(gradcheck::GradcheckArgs),
    /// Time simulation and forward+backward steps on the standard random herd.
    Bench(bench::BenchArgs),
    /// Fit the 12 force parameters (and the speed model) to a clip's fields; export a parameter set.
    Fit(fit::FitArgs),
    /// Extract clip fields from an overhead video (needs the `video` feature).
    Extract(extract::ExtractArgs),
    /// Validate parameter sets on the held-out part of a clip (errors, polarization, angular
    /// momentum, aspect ratio) and write a report folder.
    Validate(validate::ValidateArgs),
    /// Score parameter sets on held-out tracks: displacement errors of rollouts from the tracked
    /// animals (neighbours replayed or simulated) beside constant velocity and the generic and
    /// default sets, paired verdicts, and free runs' motion distributions against the tracks'.
    ValidateTracks(validate_tracks::ValidateTracksArgs),
    /// Fit and validate a clip with each of the paper's switches off in turn (occlusion, angular
    /// perception, density term, direction-variance matching, speed–density table): Table 4.
    Ablate(ablate::AblateArgs),
    /// Simulate a herd in an authored scene (arrows, destination, obstacles, behaviour regions).
    Author(author::AuthorArgs),
    /// Make a synthetic clip with known parameters (fields, truth.json, trajectories.csv).
    Synth(synth::SynthArgs),
    /// Convert the public Herds-From-Video extractor's text files into a clip folder.
    ImportReference(import_reference::ImportArgs),
    /// Turn tracked trajectories (herdfit.tracks/1, ETH/UCY, idtracker.ai/trajectorytools .npy)
    /// into a clip folder of fields that `fit` and `validate` read.
    ImportTracks(import_tracks::ImportTracksArgs),
    /// Summarise a clip: grid, frames, agents, speed model, polarization, angular momentum.
    FieldsInfo(fields_info::FieldsInfoArgs),
    /// The built-in walk-through: a synthetic herd rendered to video, extracted, fitted on the first
    /// half from a generic start, validated on the second half; prints a summary.
    Demo(demo::DemoArgs),
    /// Line-formation flocks (V, U, J, line) from a marked example: synth, extract, animate.
    #[command(subcommand)]
    Flock(flock::FlockCommand),
    /// Crowds learnt from tracked trajectories (Lee et al. 2007): learn, simulate, evaluate, compare.
    #[command(subcommand)]
    Crowd(crowd::CrowdCommand),
    /// 3D flocks from 2D tracks (Lin's thesis): run, synth, project, evaluate, camera.
    #[command(subcommand)]
    Lift(lift::LiftCommand),
    /// Any tracks file as an animated glTF 2.0 binary (.glb) for Blender and game engines.
    ExportGltf(export_gltf::ExportGltfArgs),
}

/// Runs a parsed command line as one transaction (issue #47): every number checked finite
/// ([`numbers`]), the output plan derived from the paths' roles ([`paths::plan_of`]) and opened,
/// the verb run, and its outputs renamed into place together — or, on an error or a panic, all
/// removed.
pub fn execute(m: &clap::ArgMatches) -> Result<()> {
    use crate::data::atomic::plan;
    use clap::{CommandFactory, FromArgMatches};
    let cmd = Cli::command();
    numbers::check(&cmd, m)?;
    let cli = Cli::from_arg_matches(m).map_err(|e| crate::Error::invalid(e.to_string()))?;
    paths::plan_of(&cmd, m).begin()?;
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| run(cli))) {
        Ok(Ok(())) => plan::finish(),
        Ok(Err(e)) => {
            plan::abort();
            Err(e)
        }
        Err(p) => {
            plan::abort();
            std::panic::resume_unwind(p)
        }
    }
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(a) => simulate::exec(a),
        Command::Gradcheck(a) => gradcheck::exec(a),
        Command::Bench(a) => bench::exec(a),
        Command::Fit(a) if a.objective == fit_objective::Objective::Tracks => track_fit::exec(a),
        Command::Fit(a) => fit::exec(a),
        Command::Extract(a) => extract::exec(a),
        Command::Validate(a) => validate::exec(a),
        Command::ValidateTracks(a) => validate_tracks::exec(a),
        Command::Ablate(a) => ablate::exec(a),
        Command::Author(a) => author::exec(a),
        Command::Synth(a) => synth::exec(a),
        Command::ImportReference(a) => import_reference::exec(a),
        Command::ImportTracks(a) => import_tracks::exec(a),
        Command::FieldsInfo(a) => fields_info::exec(a),
        Command::Demo(a) => demo::exec(a),
        Command::Flock(c) => flock::run(c),
        Command::Crowd(c) => crowd::run(c),
        Command::Lift(c) => lift::run(c),
        Command::ExportGltf(a) => export_gltf::run(a),
    }
}
