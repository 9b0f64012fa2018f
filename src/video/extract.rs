//! Clip fields from an overhead video (paper §4): stabilisation by CSRT-tracked anchors and eq. 1,
//! segmentation against a temporal-median background (and the body colour), Farneback optical
//! flow, and per-cell density, mean velocity and direction variance.
//!
//! Coordinates: the global frame is the first frame's image. A pixel (u, v) of it is the world
//! point (u / L, (H − v) / L) in body lengths (L = body length in pixels, y up), so a video of
//! `herdfit synth --video` maps back onto the world of its trajectories. The grid has square cells
//! of max(W, H) / N pixels, `nx = ⌈W / cell⌉` by `ny = ⌈H / cell⌉`, origin at the bottom-left corner.

use crate::data::{ClipFields, ClipMeta, ClipSpeed, CLIP_SCHEMA};
use crate::error::{Error, Result};
use crate::measure::speed_density_table;
use ndarray::{Array2, Array3, Array4};
use opencv::core::{Mat, Point, Rect, Scalar, Size, Vec3b, CV_8UC1};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc, tracking, video, videoio};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Every setting of an extraction (recorded in `clip.json`; loadable with `--config`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractConfig {
    /// Cells along the longer side of the frame.
    pub grid: usize,
    /// Body length in pixels.
    pub body_length_px: f64,
    /// Body colour (RGB) for the colour-distance test; none: background difference only.
    pub body_colour: Option<[u8; 3]>,
    /// Largest Euclidean RGB distance to the body colour of a herd pixel.
    pub colour_threshold: f64,
    /// Smallest per-channel difference to the background of a herd pixel.
    pub background_threshold: f64,
    /// Body pixels per animal; estimated as an ellipse of L × 0.4 L when absent.
    pub body_pixels: Option<f64>,
    /// Anchor rectangles x,y,w,h in the first frame; empty: static camera.
    pub anchors: Vec<[i32; 4]>,
    /// Background image; none: per-pixel temporal median of sampled stabilised frames.
    pub background: Option<PathBuf>,
    /// Obstacle mask (non-zero = obstacle), the size of the video frame.
    pub obstacles: Option<PathBuf>,
    /// Frames used, start..end (end exclusive); all when absent.
    pub frames: Option<[usize; 2]>,
    /// Smoothing window (frames) of the camera path and of the velocities.
    pub smooth: usize,
    /// Processing width limit: frames are scaled down so the longer side is at most this many
    /// pixels (flow and segmentation run there).
    pub max_side: usize,
}

impl Default for ExtractConfig {
    fn default() -> Self {
        ExtractConfig {
            grid: 20,
            body_length_px: 10.0,
            body_colour: None,
            colour_threshold: 60.0,
            background_threshold: 30.0,
            body_pixels: None,
            anchors: Vec::new(),
            background: None,
            obstacles: None,
            frames: None,
            smooth: 9,
            max_side: 480,
        }
    }
}

fn cv(path: &Path) -> impl Fn(opencv::Error) -> Error + '_ {
    move |e| Error::file(path, format!("OpenCV: {}", e.message))
}

/// A similarity transform p' = s R(a) p + t (frame-t pixels → first-frame pixels).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Similarity {
    pub scale: f64,
    pub angle: f64,
    pub t: [f64; 2],
}

impl Similarity {
    const IDENTITY: Similarity = Similarity {
        scale: 1.0,
        angle: 0.0,
        t: [0.0, 0.0],
    };

    /// The inverse transform.
    fn inverse(&self) -> Similarity {
        let s = 1.0 / self.scale;
        let (c, sn) = (self.angle.cos() * s, (-self.angle).sin() * s);
        Similarity {
            scale: s,
            angle: -self.angle,
            t: [
                -(c * self.t[0] - sn * self.t[1]),
                -(sn * self.t[0] + c * self.t[1]),
            ],
        }
    }

    fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let (c, s) = (self.angle.cos() * self.scale, self.angle.sin() * self.scale);
        [
            c * p[0] - s * p[1] + self.t[0],
            s * p[0] + c * p[1] + self.t[1],
        ]
    }

    /// The least-squares similarity mapping points `from` onto `to` (2-D Umeyama).
    fn fit(from: &[[f64; 2]], to: &[[f64; 2]]) -> Similarity {
        let n = from.len() as f64;
        let mean = |v: &[[f64; 2]]| {
            let s = v.iter().fold([0.0, 0.0], |a, p| [a[0] + p[0], a[1] + p[1]]);
            [s[0] / n, s[1] / n]
        };
        let (mf, mt) = (mean(from), mean(to));
        let (mut a, mut b, mut var) = (0.0, 0.0, 0.0);
        for (p, q) in from.iter().zip(to) {
            let (x, y) = (p[0] - mf[0], p[1] - mf[1]);
            let (u, v) = (q[0] - mt[0], q[1] - mt[1]);
            a += x * u + y * v;
            b += x * v - y * u;
            var += x * x + y * y;
        }
        if var < 1e-9 {
            return Similarity {
                scale: 1.0,
                angle: 0.0,
                t: [mt[0] - mf[0], mt[1] - mf[1]],
            };
        }
        let angle = b.atan2(a);
        let scale = (a * a + b * b).sqrt() / var;
        let r = Similarity {
            scale,
            angle,
            t: [0.0, 0.0],
        }
        .apply(mf);
        Similarity {
            scale,
            angle,
            t: [mt[0] - r[0], mt[1] - r[1]],
        }
    }
}

struct Video {
    cap: videoio::VideoCapture,
    path: PathBuf,
    w: usize,
    h: usize,
    fps: f64,
    count: usize,
}

/// Runs `f` with the process's stderr sent to /dev/null: FFmpeg and OpenCV print multi-line
/// diagnostics while probing corrupt files, and herdfit's errors are one line.
pub fn quietly<T>(f: impl FnOnce() -> T) -> T {
    #[cfg(unix)]
    // SAFETY: plain descriptor juggling on fd 2; restored before returning.
    unsafe {
        let saved = libc::dup(2);
        let null = libc::open(c"/dev/null".as_ptr(), libc::O_WRONLY);
        if saved >= 0 && null >= 0 {
            libc::dup2(null, 2);
            let r = f();
            libc::dup2(saved, 2);
            libc::close(null);
            libc::close(saved);
            return r;
        }
        if null >= 0 {
            libc::close(null);
        }
        if saved >= 0 {
            libc::close(saved);
        }
    }
    f()
}

fn open(path: &Path) -> Result<Video> {
    if path.is_dir() {
        return Err(Error::file(path, "is a folder, not a video file"));
    }
    if !path.is_file() {
        return Err(Error::file(path, "cannot read: no such file"));
    }
    std::fs::File::open(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let _ = opencv::core::set_log_level(opencv::core::LogLevel::LOG_LEVEL_SILENT);
    let cap = quietly(|| videoio::VideoCapture::from_file(path.as_os_str(), videoio::CAP_FFMPEG))
        .map_err(cv(path))?;
    if !cap.is_opened().map_err(cv(path))? {
        return Err(Error::file(
            path,
            "cannot open as a video (corrupt or unknown format)",
        ));
    }
    let w = cap.get(videoio::CAP_PROP_FRAME_WIDTH).map_err(cv(path))? as usize;
    let h = cap.get(videoio::CAP_PROP_FRAME_HEIGHT).map_err(cv(path))? as usize;
    let fps = cap.get(videoio::CAP_PROP_FPS).map_err(cv(path))?;
    let count = cap
        .get(videoio::CAP_PROP_FRAME_COUNT)
        .map_err(cv(path))?
        .max(0.0) as usize;
    if w == 0 || h == 0 {
        return Err(Error::file(path, "the video has no frames of a known size"));
    }
    Ok(Video {
        cap,
        path: path.to_path_buf(),
        w,
        h,
        fps: if fps.is_finite() && fps > 0.0 {
            fps
        } else {
            25.0
        },
        count,
    })
}

impl Video {
    fn rewind(&mut self) -> Result<()> {
        *self = open(&self.path)?;
        Ok(())
    }

    /// Next BGR frame, or None at the end.
    fn next(&mut self) -> Result<Option<Mat>> {
        let mut m = Mat::default();
        let ok = quietly(|| self.cap.read(&mut m)).map_err(cv(&self.path))?;
        if !ok || m.empty() {
            return Ok(None);
        }
        if m.cols() as usize != self.w || m.rows() as usize != self.h || m.channels() != 3 {
            return Err(Error::file(
                &self.path,
                "a frame has another size or is not colour",
            ));
        }
        Ok(Some(m))
    }
}

fn smooth_path(raw: &[Similarity], window: usize) -> Vec<Similarity> {
    let half = window / 2;
    (0..raw.len())
        .map(|i| {
            let lo = i.saturating_sub(half);
            let hi = (i + half + 1).min(raw.len());
            let n = (hi - lo) as f64;
            let mut acc = [0.0; 4];
            for r in &raw[lo..hi] {
                acc[0] += r.scale.ln();
                acc[1] += r.angle;
                acc[2] += r.t[0];
                acc[3] += r.t[1];
            }
            Similarity {
                scale: (acc[0] / n).exp(),
                angle: acc[1] / n,
                t: [acc[2] / n, acc[3] / n],
            }
        })
        .collect()
}

/// Result of an extraction.
pub struct Extraction {
    pub clip: ClipFields,
    /// Camera path (frame → first frame), smoothed.
    pub camera: Vec<Similarity>,
    /// Preview PNGs to write (name, bytes).
    pub previews: Vec<(String, Vec<u8>)>,
}

/// Runs the extraction. `progress(done, total)` after every processed frame of each pass.
pub fn extract(
    path: &Path,
    cfg: &ExtractConfig,
    preview_every: Option<usize>,
    mut progress: impl FnMut(&str, usize, usize),
) -> Result<Extraction> {
    if cfg.grid == 0 {
        return Err(Error::invalid("--grid must be ≥ 1"));
    }
    if !(cfg.body_length_px.is_finite() && cfg.body_length_px > 0.0) {
        return Err(Error::invalid("--body-length-px must be > 0"));
    }
    if cfg.smooth == 0 {
        return Err(Error::invalid("--smooth must be ≥ 1"));
    }
    let mut vid = open(path)?;
    let (w, h) = (vid.w, vid.h);
    let (first, last) = match cfg.frames {
        Some([a, b]) => (a, b),
        None => (0, usize::MAX),
    };
    if first >= last {
        return Err(Error::invalid(format!("--frames {first}..{last} is empty")));
    }
    if vid.count > 0 && first >= vid.count {
        return Err(Error::invalid(format!(
            "--frames {first}..{last} is out of range: the video has {} frames",
            vid.count
        )));
    }
    for (k, a) in cfg.anchors.iter().enumerate() {
        let [x, y, aw, ah] = *a;
        if x < 0 || y < 0 || aw < 4 || ah < 4 || (x + aw) as usize > w || (y + ah) as usize > h {
            return Err(Error::invalid(format!(
                "--anchor {k} ({x},{y},{aw},{ah}) is not a rectangle of at least 4×4 inside the {w}×{h} frame"
            )));
        }
    }
    let fail = cv(path);
    // Skip to the first frame.
    for _ in 0..first {
        if vid.next()?.is_none() {
            return Err(Error::invalid(format!(
                "--frames starts at {first} but the video ends before"
            )));
        }
    }
    // CSRT only has to find the anchor to within the ±24 px refinement window, so a lighter
    // tracker than OpenCV's defaults will do: a smaller template, fewer scales and iterations.
    let csrt_params = || -> Result<tracking::TrackerCSRT_Params> {
        use opencv::tracking::TrackerCSRT_ParamsTrait;
        let mut p = tracking::TrackerCSRT_Params::default().map_err(cv(path))?;
        p.set_template_size(96.0);
        p.set_number_of_scales(9);
        p.set_admm_iterations(2);
        Ok(p)
    };
    let t_start = std::time::Instant::now();
    let track_scale = (cfg.max_side as f64 / w.max(h) as f64).min(1.0);
    // Pass A: camera path from the anchors.
    let mut raw = Vec::new();
    let mut frames = 0usize;
    {
        let mut trackers = Vec::new();
        let mut origin_pts: Vec<[f64; 2]> = Vec::new();
        let mut origin_w: Vec<f64> = Vec::new();
        let mut anchor_h: Vec<f64> = Vec::new();
        let mut first_frame = Mat::default();
        // A second thread decodes and downsizes frames while this one tracks.
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<(Mat, Mat)>>(4);
        let anchors_on = !cfg.anchors.is_empty();
        let total_frames = vid.count.saturating_sub(first).min(last - first);
        let vid_a = &mut vid;
        std::thread::scope(|scope| -> Result<()> {
            let producer = scope.spawn(move || {
                let mut k = 0usize;
                while first + k < last {
                    let item = (|| -> Result<Option<(Mat, Mat)>> {
                        let Some(frame) = vid_a.next()? else {
                            return Ok(None);
                        };
                        // CSRT runs on a frame scaled to the processing size; positions are refined
                        // at full resolution below.
                        let small = if track_scale < 1.0 && anchors_on {
                            let mut m = Mat::default();
                            imgproc::resize(
                                &frame,
                                &mut m,
                                Size::new(0, 0),
                                track_scale,
                                track_scale,
                                imgproc::INTER_AREA,
                            )
                            .map_err(cv(path))?;
                            m
                        } else {
                            Mat::default()
                        };
                        Ok(Some((frame, small)))
                    })();
                    if !forward(&tx, item) {
                        return;
                    }
                    k += 1;
                }
            });
            while let Ok(item) = rx.recv() {
                let (frame, small) = item?;
                let small = if small.empty() {
                    frame.try_clone().map_err(&fail)?
                } else {
                    small
                };
                let sc = |r: Rect| -> Rect {
                    Rect::new(
                        (r.x as f64 * track_scale).round() as i32,
                        (r.y as f64 * track_scale).round() as i32,
                        ((r.width as f64 * track_scale).round() as i32).max(4),
                        ((r.height as f64 * track_scale).round() as i32).max(4),
                    )
                };
                if frames == 0 {
                    first_frame = frame.try_clone().map_err(&fail)?;
                    for a in &cfg.anchors {
                        let mut t =
                            tracking::TrackerCSRT::create(&csrt_params()?).map_err(&fail)?;
                        let r = Rect::new(a[0], a[1], a[2], a[3]);
                        t.init(&small, sc(r)).map_err(&fail)?;
                        trackers.push(t);
                        origin_pts.push([
                            a[0] as f64 + a[2] as f64 / 2.0,
                            a[1] as f64 + a[3] as f64 / 2.0,
                        ]);
                        origin_w.push(a[2] as f64);
                        anchor_h.push(a[3] as f64);
                    }
                    raw.push(Similarity::IDENTITY);
                } else if trackers.is_empty() {
                    raw.push(Similarity::IDENTITY);
                } else {
                    let prev = *raw.last().unwrap_or(&Similarity::IDENTITY);
                    let inv = prev.inverse();
                    let mut pts = Vec::with_capacity(trackers.len());
                    let mut scales = Vec::new();
                    for (k, t) in trackers.iter_mut().enumerate() {
                        let mut r = Rect::default();
                        if !t.update(&small, &mut r).map_err(&fail)? {
                            continue;
                        }
                        let r = Rect::new(
                            (r.x as f64 / track_scale).round() as i32,
                            (r.y as f64 / track_scale).round() as i32,
                            (r.width as f64 / track_scale).round() as i32,
                            (r.height as f64 / track_scale).round() as i32,
                        );
                        let coarse = [
                            r.x as f64 + r.width as f64 / 2.0,
                            r.y as f64 + r.height as f64 / 2.0,
                        ];
                        // Refine the CSRT position by normalised cross-correlation of the anchor's
                        // first-frame patch (as seen under the previous camera) within ±24 px.
                        let q = inv.apply(origin_pts[k]);
                        let (tw, th) = (
                            (origin_w[k] * inv.scale) as i32,
                            (anchor_h[k] * inv.scale) as i32,
                        );
                        let tr = Rect::new(
                            (q[0] - tw as f64 / 2.0) as i32,
                            (q[1] - th as f64 / 2.0) as i32,
                            tw,
                            th,
                        );
                        let margin = 24;
                        let sr = Rect::new(
                            (coarse[0] as i32 - tw / 2 - margin).max(0),
                            (coarse[1] as i32 - th / 2 - margin).max(0),
                            0,
                            0,
                        );
                        let sr = Rect::new(
                            sr.x,
                            sr.y,
                            (tw + 2 * margin).min(w as i32 - sr.x),
                            (th + 2 * margin).min(h as i32 - sr.y),
                        );
                        let inside = |r: &Rect| {
                            r.x >= 0
                                && r.y >= 0
                                && r.width > 4
                                && r.height > 4
                                && r.x + r.width <= w as i32
                                && r.y + r.height <= h as i32
                        };
                        let mut centre = coarse;
                        if inside(&tr)
                            && inside(&sr)
                            && sr.width > tr.width
                            && sr.height > tr.height
                        {
                            // The anchor's first-frame patch as this frame would see it under the
                            // previous camera (carries the current rotation and zoom).
                            let (c, sn) =
                                (prev.angle.cos() * prev.scale, prev.angle.sin() * prev.scale);
                            let (ox, oy) = (tr.x as f64, tr.y as f64);
                            let mm = Mat::from_slice_2d(&[
                                [c, -sn, c * ox - sn * oy + prev.t[0]],
                                [sn, c, sn * ox + c * oy + prev.t[1]],
                            ])
                            .map_err(&fail)?;
                            let mut templ = Mat::default();
                            imgproc::warp_affine(
                                &first_frame,
                                &mut templ,
                                &mm,
                                Size::new(tr.width, tr.height),
                                imgproc::INTER_LINEAR | imgproc::WARP_INVERSE_MAP,
                                opencv::core::BORDER_REFLECT,
                                Scalar::all(0.0),
                            )
                            .map_err(&fail)?;
                            let area = Mat::roi(&frame, sr).map_err(&fail)?;
                            let mut res = Mat::default();
                            imgproc::match_template(
                                &area,
                                &templ,
                                &mut res,
                                imgproc::TM_CCOEFF_NORMED,
                                &opencv::core::no_array(),
                            )
                            .map_err(&fail)?;
                            let (mut best, mut loc) = (0.0f64, Point::default());
                            opencv::core::min_max_loc(
                                &res,
                                None,
                                Some(&mut best),
                                None,
                                Some(&mut loc),
                                &opencv::core::no_array(),
                            )
                            .map_err(&fail)?;
                            if best > 0.5 {
                                // Sub-pixel peak by a parabola through the neighbours.
                                let at = |x: i32, y: i32| -> f64 {
                                    res.at_2d::<f32>(y, x).map(|v| *v as f64).unwrap_or(best)
                                };
                                let sub = |m: f64, c: f64, p: f64| {
                                    let d = m - 2.0 * c + p;
                                    if d.abs() > 1e-9 {
                                        0.5 * (m - p) / d
                                    } else {
                                        0.0
                                    }
                                };
                                let (rx, ry) = (res.cols(), res.rows());
                                let dx = if loc.x > 0 && loc.x < rx - 1 {
                                    sub(at(loc.x - 1, loc.y), best, at(loc.x + 1, loc.y))
                                } else {
                                    0.0
                                };
                                let dy = if loc.y > 0 && loc.y < ry - 1 {
                                    sub(at(loc.x, loc.y - 1), best, at(loc.x, loc.y + 1))
                                } else {
                                    0.0
                                };
                                centre = [
                                    sr.x as f64 + loc.x as f64 + dx + (q[0] - tr.x as f64),
                                    sr.y as f64 + loc.y as f64 + dy + (q[1] - tr.y as f64),
                                ];
                            }
                        }
                        pts.push((k, centre));
                        scales.push(origin_w[k] / r.width.max(1) as f64);
                    }
                    let s = if pts.len() >= 2 {
                        // Fit on all anchors; with three or more, drop those that disagree with the
                        // others by more than 2 px (a tracker that slid off) and re-initialise them
                        // where the camera says they are.
                        let fit_on = |keep: &[usize]| {
                            let from: Vec<[f64; 2]> = keep.iter().map(|&i| pts[i].1).collect();
                            let to: Vec<[f64; 2]> =
                                keep.iter().map(|&i| origin_pts[pts[i].0]).collect();
                            Similarity::fit(&from, &to)
                        };
                        // Candidates: all anchors, and (with three or more) each leave-one-out set.
                        // The camera moves little between frames, so keep the candidate closest to
                        // the previous frame's camera at the frame corners.
                        let all: Vec<usize> = (0..pts.len()).collect();
                        let mut cands = vec![all.clone()];
                        if pts.len() >= 3 {
                            for i in 0..pts.len() {
                                cands.push(all.iter().copied().filter(|&j| j != i).collect());
                            }
                        }
                        let corners = [
                            [0.0, 0.0],
                            [w as f64, 0.0],
                            [0.0, h as f64],
                            [w as f64, h as f64],
                        ];
                        let jump = |s: &Similarity| {
                            corners
                                .iter()
                                .map(|&c| {
                                    let (a, b) = (s.apply(c), prev.apply(c));
                                    (a[0] - b[0]).hypot(a[1] - b[1])
                                })
                                .fold(0.0, f64::max)
                        };
                        let (keep, sim) = cands
                            .into_iter()
                            .map(|k| {
                                let s = fit_on(&k);
                                (k, s)
                            })
                            .min_by(|a, b| jump(&a.1).total_cmp(&jump(&b.1)))
                            .unwrap_or((all.clone(), prev));
                        let resid = |i: usize| {
                            let q = sim.apply(pts[i].1);
                            let o = origin_pts[pts[i].0];
                            (q[0] - o[0]).hypot(q[1] - o[1])
                        };
                        let keep: Vec<usize> = keep
                            .into_iter()
                            .filter(|&i| resid(i) <= 2.0 || pts.len() < 3)
                            .collect();
                        for (i, &(k, _)) in pts.iter().enumerate() {
                            if keep.contains(&i) {
                                continue;
                            }
                            // Predicted position in frame t: the inverse of the camera.
                            let o = origin_pts[k];
                            let (c, sn) = (sim.angle.cos(), sim.angle.sin());
                            let d = [o[0] - sim.t[0], o[1] - sim.t[1]];
                            let p = [
                                (c * d[0] + sn * d[1]) / sim.scale,
                                (-sn * d[0] + c * d[1]) / sim.scale,
                            ];
                            let wd = origin_w[k] / sim.scale;
                            let hd = anchor_h[k] / sim.scale;
                            let r = Rect::new(
                                (p[0] - wd / 2.0) as i32,
                                (p[1] - hd / 2.0) as i32,
                                wd as i32,
                                hd as i32,
                            );
                            if r.x >= 0
                                && r.y >= 0
                                && r.x + r.width <= w as i32
                                && r.y + r.height <= h as i32
                            {
                                let mut t = tracking::TrackerCSRT::create(&csrt_params()?)
                                    .map_err(&fail)?;
                                t.init(&small, sc(r)).map_err(&fail)?;
                                trackers[k] = t;
                            }
                        }
                        sim
                    } else if let Some((k, p)) = pts.first() {
                        let s = scales[0];
                        Similarity {
                            scale: s,
                            angle: 0.0,
                            t: [origin_pts[*k][0] - s * p[0], origin_pts[*k][1] - s * p[1]],
                        }
                    } else {
                        prev // all anchors lost: keep the last camera
                    };
                    raw.push(s);
                }
                frames += 1;
                progress("stabilise", frames, total_frames);
            }
            drop(rx);
            let _ = producer.join();
            Ok(())
        })?;
    }
    if frames < 2 {
        return Err(Error::file(
            path,
            format!("only {frames} frame(s) readable in the range: need ≥ 2"),
        ));
    }
    let debug = std::env::var_os("HERDFIT_DEBUG").is_some();
    if debug {
        eprintln!("pass A (camera) done at {:?}", t_start.elapsed());
    }
    let camera = smooth_path(&raw, cfg.smooth);
    // Processing resolution.
    let scale = (cfg.max_side as f64 / w.max(h) as f64).min(1.0);
    let (pw, ph) = (
        ((w as f64) * scale).round() as usize,
        ((h as f64) * scale).round() as usize,
    );
    let warp = |m: &Mat, s: &Similarity, out: &mut Mat, interp: i32| -> Result<()> {
        let (c, sn) = (
            s.angle.cos() * s.scale * scale,
            s.angle.sin() * s.scale * scale,
        );
        let mm = Mat::from_slice_2d(&[[c, -sn, s.t[0] * scale], [sn, c, s.t[1] * scale]])
            .map_err(cv(path))?;
        imgproc::warp_affine(
            m,
            out,
            &mm,
            Size::new(pw as i32, ph as i32),
            interp,
            opencv::core::BORDER_CONSTANT,
            Scalar::all(0.0),
        )
        .map_err(cv(path))
    };
    // Background: a given image, or the per-pixel median of up to 31 sampled stabilised frames.
    let background: Vec<u8> = match &cfg.background {
        Some(bg) => {
            let img = imgcodecs::imread(bg.as_os_str(), imgcodecs::IMREAD_COLOR).map_err(cv(bg))?;
            if img.empty() {
                return Err(Error::file(bg, "cannot read as an image"));
            }
            if img.cols() as usize != w || img.rows() as usize != h {
                return Err(Error::file(
                    bg,
                    format!("is {}×{}, the video is {w}×{h}", img.cols(), img.rows()),
                ));
            }
            let mut out = Mat::default();
            warp(&img, &Similarity::IDENTITY, &mut out, imgproc::INTER_AREA)?;
            out.data_bytes().map_err(cv(path))?.to_vec()
        }
        None => {
            let samples = frames.min(31);
            let pick: Vec<usize> = (0..samples)
                .map(|k| k * (frames - 1) / (samples - 1).max(1))
                .collect();
            vid.rewind()?;
            for _ in 0..first {
                vid.next()?;
            }
            let mut stack: Vec<Vec<u8>> = Vec::with_capacity(samples);
            let mut masks: Vec<Vec<u8>> = Vec::with_capacity(samples);
            let ones =
                Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC1, Scalar::all(255.0))
                    .map_err(&fail)?;
            for (i, cam) in camera.iter().enumerate() {
                let Some(f) = vid.next()? else { break };
                if pick.contains(&i) {
                    let (mut o, mut m) = (Mat::default(), Mat::default());
                    warp(&f, cam, &mut o, imgproc::INTER_LINEAR)?;
                    warp(&ones, cam, &mut m, imgproc::INTER_NEAREST)?;
                    stack.push(o.data_bytes().map_err(&fail)?.to_vec());
                    masks.push(m.data_bytes().map_err(&fail)?.to_vec());
                }
                progress("background", i + 1, frames);
            }
            let mut bg = vec![0u8; pw * ph * 3];
            let mut vals = Vec::with_capacity(stack.len());
            for p in 0..pw * ph {
                for c in 0..3 {
                    vals.clear();
                    for (s, m) in stack.iter().zip(&masks) {
                        if m[p] > 0 {
                            vals.push(s[p * 3 + c]);
                        }
                    }
                    if !vals.is_empty() {
                        vals.sort_unstable();
                        bg[p * 3 + c] = vals[vals.len() / 2];
                    }
                }
            }
            bg
        }
    };
    if debug {
        eprintln!("background done at {:?}", t_start.elapsed());
    }
    // Grid.
    let cell_px = w.max(h) as f64 / cfg.grid as f64;
    let nx = (w as f64 / cell_px).ceil() as usize;
    let ny = (h as f64 / cell_px).ceil() as usize;
    let cells = nx * ny;
    let cell_of: Vec<i32> = (0..pw * ph)
        .map(|p| {
            let (u, v) = ((p % pw) as f64 + 0.5, (p / pw) as f64 + 0.5);
            let (x, y) = (u / scale, h as f64 - v / scale);
            let ix = ((x / cell_px) as usize).min(nx - 1);
            let iy = ((y.max(0.0) / cell_px) as usize).min(ny - 1);
            (iy * nx + ix) as i32
        })
        .collect();
    let obstacles = match &cfg.obstacles {
        None => Array2::<u8>::zeros((ny, nx)),
        Some(mp) => {
            let img =
                imgcodecs::imread(mp.as_os_str(), imgcodecs::IMREAD_GRAYSCALE).map_err(cv(mp))?;
            if img.empty() {
                return Err(Error::file(mp, "cannot read as an image"));
            }
            if img.cols() as usize != w || img.rows() as usize != h {
                return Err(Error::file(
                    mp,
                    format!("is {}×{}, the video is {w}×{h}", img.cols(), img.rows()),
                ));
            }
            let data = img.data_bytes().map_err(cv(mp))?;
            let (mut on, mut all) = (vec![0usize; cells], vec![0usize; cells]);
            for (p, &v) in data.iter().enumerate() {
                let (x, y) = ((p % w) as f64 + 0.5, h as f64 - (p / w) as f64 - 0.5);
                let c = ((y / cell_px) as usize).min(ny - 1) * nx
                    + ((x / cell_px) as usize).min(nx - 1);
                all[c] += 1;
                if v > 0 {
                    on[c] += 1;
                }
            }
            Array2::from_shape_fn((ny, nx), |(iy, ix)| {
                let c = iy * nx + ix;
                u8::from(all[c] > 0 && on[c] * 2 > all[c])
            })
        }
    };
    // Pass C: segmentation, flow, per-cell sums.
    let body_px = cfg
        .body_pixels
        .unwrap_or(std::f64::consts::PI / 4.0 * cfg.body_length_px * 0.4 * cfg.body_length_px);
    if !(body_px.is_finite() && body_px > 0.0) {
        return Err(Error::invalid("--body-pixels must be > 0"));
    }
    let body_px_proc = body_px * scale * scale;
    let morph = cfg.body_length_px * 0.4 * scale >= 6.0;
    let to_bl_s = vid.fps / (cfg.body_length_px * scale);
    vid.rewind()?;
    for _ in 0..first {
        vid.next()?;
    }
    let ones = Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC1, Scalar::all(255.0))
        .map_err(&fail)?;
    let mut count = vec![vec![0.0f64; cells]; frames];
    let mut fsum = vec![vec![[0.0f64; 2]; cells]; frames];
    let mut var = vec![vec![0.0f64; cells]; frames];
    let mut speeds: Vec<f64> = Vec::new();
    let mut prev_grey: Option<Mat> = None;
    let mut previews = Vec::new();
    let kernel = imgproc::get_structuring_element(
        imgproc::MORPH_ELLIPSE,
        Size::new(3, 3),
        Point::new(-1, -1),
    )
    .map_err(&fail)?;
    let mut first_flow: Option<usize> = None;
    // Two-stage pipeline: a second thread decodes, stabilises and segments frames while this one
    // runs the optical flow and accumulates the cells.
    type Stage = (Mat, Vec<u8>, Mat);
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Stage>>(4);
    std::thread::scope(|scope| -> Result<()> {
        let producer = {
            let tx = tx.clone();
            let vid = &mut vid;
            let camera = &camera;
            let background = &background;
            let ones = &ones;
            let kernel = &kernel;
            let warp = &warp;
            scope.spawn(move || {
                for cam in camera.iter() {
                    let item = (|| -> Result<Option<Stage>> {
                        let fail = cv(path);
                        let Some(f) = vid.next()? else {
                            return Ok(None);
                        };
                        let (mut st, mut valid) = (Mat::default(), Mat::default());
                        warp(&f, cam, &mut st, imgproc::INTER_LINEAR)?;
                        warp(ones, cam, &mut valid, imgproc::INTER_NEAREST)?;
                        let px = st.data_bytes().map_err(&fail)?;
                        let vm = valid.data_bytes().map_err(&fail)?;
                        let mut herd = vec![0u8; pw * ph];
                        for p in 0..pw * ph {
                            if vm[p] == 0 {
                                continue;
                            }
                            let (b, g, r) =
                                (px[p * 3] as f64, px[p * 3 + 1] as f64, px[p * 3 + 2] as f64);
                            let d = (b - background[p * 3] as f64)
                                .abs()
                                .max((g - background[p * 3 + 1] as f64).abs())
                                .max((r - background[p * 3 + 2] as f64).abs());
                            let mut on = d > cfg.background_threshold;
                            if let Some(c) = cfg.body_colour {
                                let dist = ((r - c[0] as f64).powi(2)
                                    + (g - c[1] as f64).powi(2)
                                    + (b - c[2] as f64).powi(2))
                                .sqrt();
                                on = on && dist < cfg.colour_threshold;
                            }
                            herd[p] = if on { 255 } else { 0 };
                        }
                        if morph {
                            let m = Mat::from_slice(&herd)
                                .map_err(&fail)?
                                .reshape(1, ph as i32)
                                .map_err(&fail)?
                                .try_clone()
                                .map_err(&fail)?;
                            let mut o = Mat::default();
                            imgproc::morphology_ex(
                                &m,
                                &mut o,
                                imgproc::MORPH_OPEN,
                                &kernel,
                                Point::new(-1, -1),
                                1,
                                opencv::core::BORDER_CONSTANT,
                                Scalar::all(0.0),
                            )
                            .map_err(&fail)?;
                            herd.copy_from_slice(o.data_bytes().map_err(&fail)?);
                        }

                        let mut grey = Mat::default();
                        imgproc::cvt_color(&st, &mut grey, imgproc::COLOR_BGR2GRAY, 0)
                            .map_err(&fail)?;
                        Ok(Some((st, herd, grey)))
                    })();
                    if !forward(&tx, item) {
                        return;
                    }
                }
            })
        };
        drop(tx);
        for i in 0..frames {
            let Ok(item) = rx.recv() else { break };
            let (st, herd, grey) = item?;
            for p in 0..pw * ph {
                if herd[p] > 0 {
                    count[i][cell_of[p] as usize] += 1.0;
                }
            }
            if let Some(pg) = &prev_grey {
                let mut flow = Mat::default();
                video::calc_optical_flow_farneback(pg, &grey, &mut flow, 0.5, 2, 13, 2, 5, 1.1, 0)
                    .map_err(&fail)?;
                let fl: &[opencv::core::Vec2f] = flow.data_typed().map_err(&fail)?;
                let mut sum = vec![[0.0f64; 2]; cells];
                for p in 0..pw * ph {
                    if herd[p] > 0 {
                        let c = cell_of[p] as usize;
                        let v = [fl[p][0] as f64 * to_bl_s, -(fl[p][1] as f64) * to_bl_s];
                        sum[c][0] += v[0];
                        sum[c][1] += v[1];
                        speeds.push((v[0] * v[0] + v[1] * v[1]).sqrt());
                    }
                }
                // Direction variance about each cell's mean flow direction.
                let mut sq = vec![0.0f64; cells];
                let mut n = vec![0.0f64; cells];
                for p in 0..pw * ph {
                    if herd[p] > 0 {
                        let c = cell_of[p] as usize;
                        let m = sum[c];
                        let d = [fl[p][0] as f64, -(fl[p][1] as f64)];
                        if d[0] == 0.0 && d[1] == 0.0 {
                            continue;
                        }
                        let a = (m[0] * d[1] - m[1] * d[0])
                            .abs()
                            .atan2(m[0] * d[0] + m[1] * d[1]);
                        sq[c] += a * a;
                        n[c] += 1.0;
                    }
                }
                for c in 0..cells {
                    if n[c] > 0.0 {
                        var[i][c] = sq[c] / n[c];
                    }
                }
                fsum[i] = sum;
                first_flow.get_or_insert(i);
            }
            if let Some(every) = preview_every {
                if i % every.max(1) == 0 {
                    previews.push((
                        format!("preview-{i:05}.png"),
                        preview_png(
                            &st, &herd, &count[i], &fsum[i], nx, ny, cell_px, scale, h, path,
                        )?,
                    ));
                }
            }
            prev_grey = Some(grey);
            progress("fields", i + 1, frames);
        }
        drop(rx);
        let _ = producer.join();
        Ok(())
    })?;
    if debug {
        eprintln!("fields done at {:?}", t_start.elapsed());
    }
    // Frame 0 has no previous frame: it takes frame 1's flow.
    if let Some(k) = first_flow {
        let (a, b) = (fsum[k].clone(), var[k].clone());
        for i in 0..k {
            fsum[i] = a.clone();
            var[i] = b.clone();
        }
    }
    // Velocity: flow sums over the smoothing window / herd pixels in it.
    let half = cfg.smooth / 2;
    let area_bl = (cell_px / cfg.body_length_px).powi(2);
    let mut density = Array3::<f32>::zeros((frames, ny, nx));
    let mut velocity = Array4::<f32>::zeros((frames, ny, nx, 2));
    let mut dir_variance = Array3::<f32>::zeros((frames, ny, nx));
    let mut samples = Vec::new();
    for i in 0..frames {
        let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(frames));
        for c in 0..cells {
            let (iy, ix) = (c / nx, c % nx);
            let n = count[i][c];
            if n <= 0.0 {
                continue;
            }
            let agents = n / body_px_proc;
            let rho = agents / area_bl;
            density[[i, iy, ix]] = rho as f32;
            let (mut s, mut k) = ([0.0; 2], 0.0);
            for j in lo..hi {
                s[0] += fsum[j][c][0];
                s[1] += fsum[j][c][1];
                k += count[j][c];
            }
            if k > 0.0 {
                let v = [s[0] / k, s[1] / k];
                velocity[[i, iy, ix, 0]] = v[0] as f32;
                velocity[[i, iy, ix, 1]] = v[1] as f32;
                samples.push((rho, (v[0] * v[0] + v[1] * v[1]).sqrt(), agents));
            }
            dir_variance[[i, iy, ix]] = var[i][c] as f32;
        }
    }
    let (mean, std_bp) = if speeds.is_empty() {
        (0.0, 0.0)
    } else {
        let m = speeds.iter().sum::<f64>() / speeds.len() as f64;
        let v = speeds.iter().map(|s| (s - m).powi(2)).sum::<f64>() / speeds.len() as f64;
        (m, v.sqrt())
    };
    let clip = ClipFields {
        meta: ClipMeta {
            schema: CLIP_SCHEMA.into(),
            fps: vid.fps,
            cell_size: cell_px / cfg.body_length_px,
            nx,
            ny,
            frames,
            origin: [0.0, 0.0],
            body_length_px: Some(cfg.body_length_px),
            body_pixel_coverage: Some(body_px),
            speed: ClipSpeed {
                mean,
                // §6.2: v_σ = v_σ^bp / √N_bp.
                std: std_bp / body_px.sqrt(),
                density_table: speed_density_table(&samples),
            },
            provenance: serde_json::json!({
                "source": "extract",
                "video": path.display().to_string(),
                "video_size": [w, h],
                "first_frame": first,
                "processing_scale": scale,
                "settings": cfg,
            }),
        },
        density,
        velocity,
        dir_variance,
        obstacles,
    };
    clip.validate()?;
    Ok(Extraction {
        clip,
        camera,
        previews,
    })
}

/// Preview: the stabilised frame, herd pixels tinted red, a density heat map per cell and mean
/// velocity arrows.
#[allow(clippy::too_many_arguments)]
fn preview_png(
    st: &Mat,
    herd: &[u8],
    count: &[f64],
    flow: &[[f64; 2]],
    nx: usize,
    ny: usize,
    cell_px: f64,
    scale: f64,
    h: usize,
    path: &Path,
) -> Result<Vec<u8>> {
    let fail = cv(path);
    let mut img = st.try_clone().map_err(&fail)?;
    {
        let data = img.data_bytes_mut().map_err(&fail)?;
        for (p, &on) in herd.iter().enumerate() {
            if on > 0 {
                data[p * 3] = 0;
                data[p * 3 + 1] = 0;
                data[p * 3 + 2] = 255;
            }
        }
    }
    let max = count.iter().cloned().fold(0.0, f64::max).max(1.0);
    for iy in 0..ny {
        for ix in 0..nx {
            let c = iy * nx + ix;
            let x0 = ix as f64 * cell_px * scale;
            let y1 = (h as f64 - iy as f64 * cell_px) * scale;
            let y0 = (h as f64 - (iy + 1) as f64 * cell_px) * scale;
            let r = Rect::new(
                x0 as i32,
                y0.max(0.0) as i32,
                (cell_px * scale) as i32,
                (y1 - y0.max(0.0)) as i32,
            );
            let a = count[c] / max;
            if a > 0.0 {
                imgproc::rectangle(
                    &mut img,
                    r,
                    Scalar::new(0.0, 255.0 * a, 255.0 * (1.0 - a), 0.0),
                    1,
                    imgproc::LINE_8,
                    0,
                )
                .map_err(&fail)?;
                let f = flow[c];
                let l = (f[0] * f[0] + f[1] * f[1]).sqrt();
                if l > 1e-9 {
                    let cx = x0 + cell_px * scale / 2.0;
                    let cy = (y0 + y1) / 2.0;
                    let k = cell_px * scale * 0.45 / l;
                    imgproc::arrowed_line(
                        &mut img,
                        Point::new(cx as i32, cy as i32),
                        Point::new((cx + f[0] * k) as i32, (cy - f[1] * k) as i32),
                        Scalar::new(255.0, 255.0, 0.0, 0.0),
                        1,
                        imgproc::LINE_AA,
                        0,
                        0.3,
                    )
                    .map_err(&fail)?;
                }
            }
        }
    }
    let mut buf = opencv::core::Vector::<u8>::new();
    imgcodecs::imencode(".png", &img, &mut buf, &opencv::core::Vector::new()).map_err(&fail)?;
    let _ = Vec3b::default();
    Ok(buf.to_vec())
}

/// Hands one item of a producer thread to its consumer: `true` to go on; `false` when the stream
/// has ended (`Ok(None)`), failed (the error is passed on) or the consumer has gone.
fn forward<T>(tx: &std::sync::mpsc::SyncSender<Result<T>>, item: Result<Option<T>>) -> bool {
    match item {
        Ok(Some(x)) => tx.send(Ok(x)).is_ok(),
        Ok(None) => false,
        Err(e) => {
            let _ = tx.send(Err(e));
            false
        }
    }
}
