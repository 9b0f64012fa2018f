//! `herdfit import-tracks`: tracked trajectories → a clip folder ([`import_tracks`]).

use crate::cli::args::{choice, parse_range, with_flags};
use crate::cli::paths::{InFile, InFileOrWord, OutDir};
use crate::error::{Error, Result};
use crate::herd::import_tracks::{
    import_tracks, Arena, ImportTracksConfig, ImportTracksJob, TracksFormat,
};
use clap::Args;
use std::path::PathBuf;

const FORMATS: &[(&str, &str)] = &[
    (
        "auto",
        "by extension: .npy, .csv (herdfit.tracks/1), else ETH/UCY text",
    ),
    (
        "tracks",
        "herdfit.tracks/1 CSV with its JSON sidecar (TRAJ.csv too)",
    ),
    (
        "eth-ucy",
        "whitespace-separated `frame id x y` in metres (needs --fps, --body-length-m)",
    ),
    (
        "npy",
        "idtracker.ai / trajectorytools trajectories (pixels, y down)",
    ),
];

#[derive(Args, Debug)]
pub struct ImportTracksArgs {
    /// Tracks file: herdfit.tracks/1 CSV, ETH/UCY text, or idtracker.ai/trajectorytools .npy.
    #[arg(value_name = "TRACKS")]
    pub input: InFile,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: OutDir,
    #[arg(long, value_parser = choice::<TracksFormat>(FORMATS), default_value_t = TracksFormat::Auto)]
    pub format: TracksFormat,
    /// Frames per second (required for ETH/UCY text and plain .npy arrays; overrides the file's).
    #[arg(long, value_name = "FPS")]
    pub fps: Option<f64>,
    /// Body length in pixels, for tracks in pixels (default: what the file records).
    #[arg(long, value_name = "L")]
    pub body_length_px: Option<f64>,
    /// Body length in metres, for tracks in metres.
    #[arg(long, value_name = "L")]
    pub body_length_m: Option<f64>,
    /// Cells along the longer side of the tracks' bounding box.
    #[arg(long, value_name = "N", default_value_t = ImportTracksConfig::default().grid)]
    pub grid: usize,
    /// Cell side in BL (overrides --grid).
    #[arg(long, value_name = "C")]
    pub cell_size: Option<f64>,
    /// Frames used, a..b (b exclusive), counted from the first tracked frame.
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    /// Frames over which velocities are averaged (odd).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub smooth: usize,
    /// Obstacle cells: `open` (none), `unvisited` (cells no animal entered), `border` (the arena
    /// border the .npy records), or POLY.json ([[x, y], …] in the file's units).
    #[arg(
        long,
        value_name = "open|unvisited|border|POLY.json",
        default_value = "open"
    )]
    pub arena: InFileOrWord,
}

fn arena(s: &str) -> Result<Arena> {
    Ok(match s {
        "open" => Arena::Open,
        "unvisited" => Arena::Unvisited,
        "border" => Arena::Border,
        path => {
            let p = PathBuf::from(path);
            let text = std::fs::read_to_string(&p)
                .map_err(|e| Error::file(&p, format!("cannot read: {e}")))?;
            let poly: Vec<[f64; 2]> = serde_json::from_str(&text)
                .map_err(|e| Error::file(&p, format!("not a JSON list of [x, y] points: {e}")))?;
            Arena::Polygon(poly)
        }
    })
}

pub fn exec(a: ImportTracksArgs) -> Result<()> {
    let job = ImportTracksJob {
        input: a.input.into(),
        out: a.out.into(),
        config: ImportTracksConfig {
            format: a.format,
            fps: a.fps,
            body_length_px: a.body_length_px,
            body_length_m: a.body_length_m,
            grid: a.grid,
            cell_size: a.cell_size,
            frames: a.frames,
            smooth: a.smooth,
            arena: arena(&a.arena.text())?,
        },
    };
    let s = import_tracks(&job).map_err(|e| with_flags(e, &[]))?;
    println!("{s}");
    Ok(())
}
