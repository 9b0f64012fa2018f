//! `herdfit extract`: a settings file and flags → `ExtractJob` → `video::extract::run` → one line.

use crate::cli::args::{parse_range, parse_rgb};
use crate::cli::paths::{InFile, InFileOrWord, OutDir};
use crate::error::{Error, Result};
use clap::Args;

/// An animal count on one frame (the library's `UserCount`; mirrored here so that the command
/// line builds without the `video` feature).
#[cfg(feature = "video")]
use crate::video::extract::UserCount;
#[cfg(not(feature = "video"))]
#[derive(Clone, Debug)]
pub struct UserCount {
    pub animals: usize,
    pub frame: usize,
}

#[derive(Args, Debug)]
pub struct ExtractArgs {
    /// The overhead video, or a still image (.png, .jpg, …: a one-frame clip, needs
    /// --dir-variance).
    #[arg(value_name = "VIDEO|IMAGE")]
    pub video: InFile,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: OutDir,
    /// Settings file (the `settings` object a previous extraction recorded in clip.json); flags
    /// given on the command line override it.
    #[arg(long, value_name = "extract.json")]
    pub config: Option<InFile>,
    /// Cells along the longer side of the frame (default: cells of 3 body lengths).
    #[arg(long, value_name = "N")]
    pub grid: Option<usize>,
    /// Body length in pixels (default: estimated from the isolated animals).
    #[arg(long, value_name = "L")]
    pub body_length_px: Option<f64>,
    /// Body colour R,G,B (herd pixels must also be within --colour-threshold of it).
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb)]
    pub body_colour: Option<[u8; 3]>,
    #[arg(long, value_name = "T")]
    pub colour_threshold: Option<f64>,
    /// Per-channel difference to the background above which a pixel can be herd (default:
    /// Otsu's threshold above the noise).
    #[arg(long, value_name = "T")]
    pub background_threshold: Option<f64>,
    /// Body pixels per animal (default: the median area of the isolated animals).
    #[arg(long, value_name = "NBP")]
    pub body_pixels: Option<f64>,
    /// N animals counted on one frame (video frame index): body pixels per animal = the herd
    /// pixels of that frame / N.
    #[arg(long, value_name = "N@FRAME", value_parser = parse_count)]
    pub count: Option<UserCount>,
    /// The camera does not move: no automatic stabilisation.
    #[arg(long)]
    pub static_camera: bool,
    /// Anchor rectangle x,y,w,h of the first frame tracked with CSRT (repeat for several;
    /// `center` for the central quarter of the frame). None: automatic stabilisation on the
    /// background's features.
    #[arg(long, value_name = "x,y,w,h")]
    pub anchor: Vec<String>,
    /// `auto` (temporal median of stabilised frames) or a background image.
    #[arg(long, value_name = "auto|IMAGE")]
    pub background: Option<InFileOrWord>,
    /// Obstacles: a mask image the size of the video frame (non-zero = obstacle), or a JSON
    /// file of polygons in video pixels of the first frame (x right, y down):
    /// {"schema": "herdfit.obstacle-polygons/1", "polygons": [[[x, y], …], …]}.
    #[arg(long, value_name = "MASK.png|POLYGONS.json")]
    pub obstacles: Option<InFile>,
    /// Frames used, a..b (b exclusive).
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    /// Smoothing window (frames) for the camera path and velocities.
    #[arg(long, value_name = "K")]
    pub smooth: Option<usize>,
    /// Write preview PNGs (density and velocity over the stabilised frame) into DIR.
    #[arg(long, value_name = "DIR")]
    pub preview: Option<OutDir>,
    /// One preview every N frames.
    #[arg(long, value_name = "N", default_value_t = 25)]
    pub preview_every: usize,
    /// A still image (.png, .jpg, …; a one-frame clip, §7.2.4): its uniform direction variance
    /// in rad², set by inspection (randomly aligned animals: π²/3 ≈ 3.29; aligned: 0).
    #[arg(long, value_name = "V")]
    pub dir_variance: Option<f64>,
}

/// A `--count` value `N@FRAME`.
fn parse_count(s: &str) -> std::result::Result<UserCount, String> {
    let bad = || format!("'{s}' is not N@FRAME (animals counted on a frame, e.g. 8@0)");
    let (n, f) = s.split_once('@').ok_or_else(bad)?;
    let animals = n.trim().parse::<usize>().map_err(|_| bad())?;
    let frame = f.trim().parse::<usize>().map_err(|_| bad())?;
    Ok(UserCount { animals, frame })
}

#[cfg(not(feature = "video"))]
pub fn exec(a: ExtractArgs) -> Result<()> {
    Err(Error::file(
        &a.video,
        "this herdfit was built without the `video` feature (OpenCV)",
    ))
}

/// An `--anchor` value: `x,y,w,h`, or `center` / `centre`.
#[cfg(feature = "video")]
fn parse_anchor(s: &str) -> Result<[i32; 4]> {
    if s == "center" || s == "centre" {
        return Ok(crate::video::extract::CENTRE_ANCHOR);
    }
    let v: Vec<i32> = s
        .split(',')
        .map(|t| t.trim().parse::<i32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| Error::invalid(format!("--anchor '{s}' is not x,y,w,h")))?;
    if v.len() != 4 {
        return Err(Error::invalid(format!("--anchor '{s}' is not x,y,w,h")));
    }
    Ok([v[0], v[1], v[2], v[3]])
}

#[cfg(feature = "video")]
pub fn exec(a: ExtractArgs) -> Result<()> {
    use crate::cli::args::with_settings;
    use crate::video::extract::{run, ExtractConfig, ExtractJob};
    // The settings file, parsed twice: into the config, and as JSON to know which keys it sets.
    let (mut cfg, settings) = match &a.config {
        Some(p) => {
            crate::data::atomic::note_input(p);
            let text = std::fs::read_to_string(p)
                .map_err(|e| Error::file(p, format!("cannot read: {e}")))?;
            let cfg = serde_json::from_str::<ExtractConfig>(&text)
                .map_err(|e| Error::file(p, format!("not an extraction settings file: {e}")))?;
            let json: serde_json::Value = serde_json::from_str(&text)
                .map_err(|e| Error::file(p, format!("not an extraction settings file: {e}")))?;
            (cfg, Some((p.clone(), json)))
        }
        None => (ExtractConfig::default(), None),
    };
    // Flags given on the command line override the settings file.
    let set = |v: &mut f64, x: Option<f64>| *v = x.unwrap_or(*v);
    cfg.grid = a.grid.or(cfg.grid);
    cfg.body_length_px = a.body_length_px.or(cfg.body_length_px);
    cfg.body_colour = a.body_colour.or(cfg.body_colour);
    set(&mut cfg.colour_threshold, a.colour_threshold);
    cfg.background_threshold = a.background_threshold.or(cfg.background_threshold);
    cfg.count = a.count.or(cfg.count);
    if a.static_camera {
        cfg.stabilise = false;
    }
    cfg.body_pixels = a.body_pixels.or(cfg.body_pixels);
    cfg.smooth = a.smooth.unwrap_or(cfg.smooth);
    cfg.frames = a.frames.map(|(x, y)| [x, y]).or(cfg.frames);
    cfg.obstacles = a.obstacles.clone().map(Into::into).or(cfg.obstacles);
    cfg.dir_variance = a.dir_variance.or(cfg.dir_variance);
    match a.background.as_ref() {
        None => {}
        Some(b) if b.text() == "auto" => cfg.background = None,
        Some(p) => cfg.background = Some(p.path()),
    }
    if !a.anchor.is_empty() {
        cfg.anchors = a
            .anchor
            .iter()
            .map(|s| parse_anchor(s))
            .collect::<Result<_>>()?;
    }
    let job = ExtractJob {
        video: a.video.into(),
        out: a.out.into(),
        preview: a.preview.map(Into::into),
        preview_every: a.preview_every,
        config: cfg,
    };
    // Which keys the command line set (a bad value there is named by its flag).
    let given = |key: &str| match key {
        "grid" => a.grid.is_some(),
        "body_length_px" => a.body_length_px.is_some(),
        "body_colour" => a.body_colour.is_some(),
        "colour_threshold" => a.colour_threshold.is_some(),
        "background_threshold" => a.background_threshold.is_some(),
        "body_pixels" => a.body_pixels.is_some(),
        "anchors" => !a.anchor.is_empty(),
        "background" => a.background.is_some(),
        "obstacles" => a.obstacles.is_some(),
        "frames" => a.frames.is_some(),
        "smooth" => a.smooth.is_some(),
        "count" => a.count.is_some(),
        "dir_variance" => a.dir_variance.is_some(),
        "stabilise" => a.static_camera,
        _ => false,
    };
    let settings = settings.as_ref().map(|(p, j)| (&**p, j));
    let ex = run(&job, &mut crate::cli::Bars::default()).map_err(|e| {
        with_settings(
            e,
            &[("anchors", "--anchor"), ("stabilise", "--static-camera")],
            settings,
            &given,
        )
    })?;
    println!("{}", ex.summary(&job.out));
    Ok(())
}
