//! Pass A of an extraction: the camera path (paper §4, eq. 1). CSRT trackers follow anchor
//! rectangles of the ground on a downsized frame; each position is refined at full resolution by
//! normalised cross-correlation with the anchor's first-frame patch warped by the previous
//! camera; a similarity per frame maps the anchors back onto their first-frame positions, with
//! leave-one-out rejection of a tracker that slid off (re-initialised where the camera says it
//! is); the path is smoothed over the extraction's window.

use super::decode::{cv, downscaled, forward, Kept, Video};
use super::ExtractConfig;
use crate::error::Result;
use opencv::core::{Mat, Point, Rect, Scalar, Size};
use opencv::prelude::*;
use opencv::{imgproc, tracking};
use serde::Serialize;
use std::path::Path;

/// A similarity transform p' = s R(a) p + t (frame-t pixels → first-frame pixels).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Similarity {
    pub scale: f64,
    pub angle: f64,
    pub t: [f64; 2],
}

impl Similarity {
    pub(super) const IDENTITY: Similarity = Similarity {
        scale: 1.0,
        angle: 0.0,
        t: [0.0, 0.0],
    };

    /// The inverse transform.
    pub(super) fn inverse(&self) -> Similarity {
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

    pub(super) fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        self.mapper()(p)
    }

    /// [`Similarity::apply`] with the rotation and zoom worked out once (the same arithmetic,
    /// for mapping many points).
    pub(super) fn mapper(&self) -> impl Fn([f64; 2]) -> [f64; 2] {
        let (c, s) = (self.angle.cos() * self.scale, self.angle.sin() * self.scale);
        let t = self.t;
        move |p| [c * p[0] - s * p[1] + t[0], s * p[0] + c * p[1] + t[1]]
    }

    /// The least-squares similarity mapping points `from` onto `to` (2-D Umeyama).
    pub(super) fn fit(from: &[[f64; 2]], to: &[[f64; 2]]) -> Similarity {
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

/// The largest distance a corner of the `w × h` frame moves under `s` (pixels).
pub(super) fn corner_shift(s: &Similarity, w: usize, h: usize) -> f64 {
    [
        [0.0, 0.0],
        [w as f64, 0.0],
        [0.0, h as f64],
        [w as f64, h as f64],
    ]
    .iter()
    .map(|&c| {
        let q = s.apply(c);
        (q[0] - c[0]).hypot(q[1] - c[1])
    })
    .fold(0.0, f64::max)
}

/// The camera path smoothed over a centred window of `window` frames (log-scale, angle and
/// translation averaged).
pub(super) fn smooth_path(raw: &[Similarity], window: usize) -> Vec<Similarity> {
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

/// CSRT settings: it only has to find the anchor to within the ±24 px refinement window, so a
/// lighter tracker than OpenCV's defaults will do (a smaller template, fewer scales and
/// iterations).
fn csrt_params(path: &Path) -> Result<tracking::TrackerCSRT_Params> {
    use opencv::tracking::TrackerCSRT_ParamsTrait;
    let mut p = tracking::TrackerCSRT_Params::default().map_err(cv(path))?;
    p.set_template_size(96.0);
    p.set_number_of_scales(9);
    p.set_admm_iterations(2);
    Ok(p)
}

/// The anchors being tracked: one CSRT tracker each, their first-frame centres and sizes, and
/// the first frame itself (for the refinement's template).
struct Anchors<'a> {
    path: &'a Path,
    trackers: Vec<opencv::core::Ptr<tracking::TrackerCSRT>>,
    origin_pts: Vec<[f64; 2]>,
    origin_w: Vec<f64>,
    anchor_h: Vec<f64>,
    first_frame: Mat,
    /// Downsizing of the frames CSRT runs on.
    track_scale: f64,
    w: usize,
    h: usize,
}

/// Pass A: the raw (unsmoothed) camera of every frame in `first..last` (frame → first frame;
/// the identity without anchors). A second thread decodes and downsizes frames while this one
/// tracks. `progress(done, total)` after every frame. The full-resolution frames `keep` names
/// (indices within the range, ascending) are returned with the path.
pub(super) fn camera_path(
    vid: &mut Video,
    path: &Path,
    cfg: &ExtractConfig,
    (first, last): (usize, usize),
    keep: &[usize],
    progress: &mut impl FnMut(&str, usize, usize),
) -> Result<(Vec<Similarity>, Kept)> {
    let (w, h) = (vid.w, vid.h);
    let fail = cv(path);
    let track_scale = (cfg.max_side as f64 / w.max(h) as f64).min(1.0);
    let mut raw = Vec::new();
    let mut kept = Vec::new();
    let mut frames = 0usize;
    let mut anchors: Option<Anchors> = None;
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<(Mat, Mat)>>(4);
    let anchors_on = !cfg.anchors.is_empty();
    let total_frames = vid.count.saturating_sub(first).min(last - first);
    std::thread::scope(|scope| -> Result<()> {
        let producer = scope.spawn(move || {
            let mut k = 0usize;
            while first + k < last {
                let item = (|| -> Result<Option<(Mat, Mat)>> {
                    let Some(frame) = vid.next()? else {
                        return Ok(None);
                    };
                    // CSRT runs on a frame scaled to the processing size; positions are refined
                    // at full resolution.
                    let small = if track_scale < 1.0 && anchors_on {
                        downscaled(&frame, track_scale, path)?
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
            match &mut anchors {
                None => {
                    anchors = Some(Anchors::new(path, cfg, &frame, &small, track_scale)?);
                    raw.push(Similarity::IDENTITY);
                }
                Some(a) if a.trackers.is_empty() => raw.push(Similarity::IDENTITY),
                Some(a) => {
                    let prev = *raw.last().unwrap_or(&Similarity::IDENTITY);
                    let (pts, scales) = a.measure(&frame, &small, &prev)?;
                    raw.push(a.camera(&pts, &scales, prev, &small)?);
                }
            }
            if keep.binary_search(&frames).is_ok() {
                kept.push((frames, frame));
            }
            frames += 1;
            progress("stabilise", frames, total_frames);
        }
        drop(rx);
        let _ = producer.join();
        Ok(())
    })?;
    Ok((raw, kept))
}

impl<'a> Anchors<'a> {
    /// Trackers started on the first frame (`small`: the frame CSRT sees).
    fn new(
        path: &'a Path,
        cfg: &ExtractConfig,
        frame: &Mat,
        small: &Mat,
        track_scale: f64,
    ) -> Result<Self> {
        let fail = cv(path);
        let mut a = Anchors {
            path,
            trackers: Vec::new(),
            origin_pts: Vec::new(),
            origin_w: Vec::new(),
            anchor_h: Vec::new(),
            first_frame: frame.try_clone().map_err(&fail)?,
            track_scale,
            w: frame.cols() as usize,
            h: frame.rows() as usize,
        };
        for r in &cfg.anchors {
            let mut t = tracking::TrackerCSRT::create(&csrt_params(path)?).map_err(&fail)?;
            let rect = Rect::new(r[0], r[1], r[2], r[3]);
            t.init(small, a.scaled(rect)).map_err(&fail)?;
            a.trackers.push(t);
            a.origin_pts.push([
                r[0] as f64 + r[2] as f64 / 2.0,
                r[1] as f64 + r[3] as f64 / 2.0,
            ]);
            a.origin_w.push(r[2] as f64);
            a.anchor_h.push(r[3] as f64);
        }
        Ok(a)
    }

    /// A full-resolution rectangle on the downsized frame CSRT runs on.
    fn scaled(&self, r: Rect) -> Rect {
        let s = self.track_scale;
        Rect::new(
            (r.x as f64 * s).round() as i32,
            (r.y as f64 * s).round() as i32,
            ((r.width as f64 * s).round() as i32).max(4),
            ((r.height as f64 * s).round() as i32).max(4),
        )
    }

    /// Every tracker's refined position in this frame, `(anchor, centre)`, and its scale
    /// relative to the first frame (trackers that lost their anchor are left out).
    #[allow(clippy::type_complexity)]
    fn measure(
        &mut self,
        frame: &Mat,
        small: &Mat,
        prev: &Similarity,
    ) -> Result<(Vec<(usize, [f64; 2])>, Vec<f64>)> {
        let fail = cv(self.path);
        let s = self.track_scale;
        let mut pts = Vec::with_capacity(self.trackers.len());
        let mut scales = Vec::new();
        for k in 0..self.trackers.len() {
            let mut r = Rect::default();
            if !self.trackers[k].update(small, &mut r).map_err(&fail)? {
                continue;
            }
            let r = Rect::new(
                (r.x as f64 / s).round() as i32,
                (r.y as f64 / s).round() as i32,
                (r.width as f64 / s).round() as i32,
                (r.height as f64 / s).round() as i32,
            );
            let coarse = [
                r.x as f64 + r.width as f64 / 2.0,
                r.y as f64 + r.height as f64 / 2.0,
            ];
            let centre = self.refine(k, frame, coarse, prev)?;
            pts.push((k, centre));
            scales.push(self.origin_w[k] / r.width.max(1) as f64);
        }
        Ok((pts, scales))
    }

    /// Refines the CSRT position `coarse` of anchor `k` by normalised cross-correlation of the
    /// anchor's first-frame patch (as seen under the previous camera) within ±24 px; `coarse`
    /// when the peak is weak or the windows leave the frame.
    fn refine(
        &self,
        k: usize,
        frame: &Mat,
        coarse: [f64; 2],
        prev: &Similarity,
    ) -> Result<[f64; 2]> {
        let fail = cv(self.path);
        let prev = *prev;
        let inv = prev.inverse();
        let q = inv.apply(self.origin_pts[k]);
        let (tw, th) = (
            (self.origin_w[k] * inv.scale) as i32,
            (self.anchor_h[k] * inv.scale) as i32,
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
            (tw + 2 * margin).min(self.w as i32 - sr.x),
            (th + 2 * margin).min(self.h as i32 - sr.y),
        );
        let inside = |r: &Rect| {
            r.x >= 0
                && r.y >= 0
                && r.width > 4
                && r.height > 4
                && r.x + r.width <= self.w as i32
                && r.y + r.height <= self.h as i32
        };
        let mut centre = coarse;
        if inside(&tr) && inside(&sr) && sr.width > tr.width && sr.height > tr.height {
            // The anchor's first-frame patch as this frame would see it under the
            // previous camera (carries the current rotation and zoom).
            let (c, sn) = (prev.angle.cos() * prev.scale, prev.angle.sin() * prev.scale);
            let (ox, oy) = (tr.x as f64, tr.y as f64);
            let mm = Mat::from_slice_2d(&[
                [c, -sn, c * ox - sn * oy + prev.t[0]],
                [sn, c, sn * ox + c * oy + prev.t[1]],
            ])
            .map_err(&fail)?;
            let mut templ = Mat::default();
            imgproc::warp_affine(
                &self.first_frame,
                &mut templ,
                &mm,
                Size::new(tr.width, tr.height),
                imgproc::INTER_LINEAR | imgproc::WARP_INVERSE_MAP,
                opencv::core::BORDER_REFLECT,
                Scalar::all(0.0),
            )
            .map_err(&fail)?;
            let area = Mat::roi(frame, sr).map_err(&fail)?;
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
        Ok(centre)
    }

    /// The camera of this frame from the anchors' positions `pts` (see the module docs);
    /// re-initialises the trackers that disagree with it.
    fn camera(
        &mut self,
        pts: &[(usize, [f64; 2])],
        scales: &[f64],
        prev: Similarity,
        small: &Mat,
    ) -> Result<Similarity> {
        let fail = cv(self.path);
        let camera = if pts.len() >= 2 {
            // Fit on all anchors; with three or more, drop those that disagree with the
            // others by more than 2 px (a tracker that slid off) and re-initialise them
            // where the camera says they are.
            let fit_on = |keep: &[usize]| {
                let from: Vec<[f64; 2]> = keep.iter().map(|&i| pts[i].1).collect();
                let to: Vec<[f64; 2]> = keep.iter().map(|&i| self.origin_pts[pts[i].0]).collect();
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
                [self.w as f64, 0.0],
                [0.0, self.h as f64],
                [self.w as f64, self.h as f64],
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
                let o = self.origin_pts[pts[i].0];
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
                let o = self.origin_pts[k];
                let (c, sn) = (sim.angle.cos(), sim.angle.sin());
                let d = [o[0] - sim.t[0], o[1] - sim.t[1]];
                let p = [
                    (c * d[0] + sn * d[1]) / sim.scale,
                    (-sn * d[0] + c * d[1]) / sim.scale,
                ];
                let wd = self.origin_w[k] / sim.scale;
                let hd = self.anchor_h[k] / sim.scale;
                let r = Rect::new(
                    (p[0] - wd / 2.0) as i32,
                    (p[1] - hd / 2.0) as i32,
                    wd as i32,
                    hd as i32,
                );
                if r.x >= 0
                    && r.y >= 0
                    && r.x + r.width <= self.w as i32
                    && r.y + r.height <= self.h as i32
                {
                    let mut t =
                        tracking::TrackerCSRT::create(&csrt_params(self.path)?).map_err(&fail)?;
                    t.init(small, self.scaled(r)).map_err(&fail)?;
                    self.trackers[k] = t;
                }
            }
            sim
        } else if let Some((k, p)) = pts.first() {
            let s = scales[0];
            Similarity {
                scale: s,
                angle: 0.0,
                t: [
                    self.origin_pts[*k][0] - s * p[0],
                    self.origin_pts[*k][1] - s * p[1],
                ],
            }
        } else {
            prev // all anchors lost: keep the last camera
        };
        Ok(camera)
    }
}
