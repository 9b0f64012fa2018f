//! Automatic camera stabilisation (paper §4, eq. 1: every frame mapped onto the reference frame by
//! a similarity): good features to track (Shi–Tomasi) on a key frame are followed into each frame
//! by pyramidal Lucas–Kanade, starting from where the previous frame's camera puts them, and a
//! RANSAC similarity fit (two-point samples, then a least-squares refit on the inliers) maps the
//! frame onto the key frame. The herd is kept out of the fit by its motion: features are spread
//! over an 8 × 6 grid of the frame (not crowded on the high-contrast animals, which move as one
//! and could outvote the ground), RANSAC keeps the largest set that agrees with one similarity,
//! and the least-squares refit tightens to 0.35 px so that animals a fraction of a pixel off do
//! not pull it. Each frame is registered against its key frame, not the previous frame, so errors
//! do not accumulate frame by frame; a new key frame (the last registered frame, with its camera)
//! starts only when a frame cannot be registered against the current one. In the first frames
//! of a clip, before the animals have moved a pixel, the herd still biases the fit (the
//! camera-path error at the frame corners is measured in RESULTS.md §2). The path is smoothed
//! over the extraction's window afterwards.
//!
//! Hand-written RANSAC rather than OpenCV's `estimateAffinePartial2D`: that needs the `calib3d`
//! module (a feature of the `opencv` crate that is not built here), and the fit is 60 lines over
//! the existing 2-D Umeyama solver (`Similarity::fit`); the sampling is seeded, so the path is
//! deterministic.

use super::camera::Similarity;
use super::decode::{cv, downscaled, forward, Kept, Video};
use super::profile;
use super::ExtractConfig;
use crate::error::{Error, Result};
use opencv::core::{Mat, Point2f, Scalar, Size, TermCriteria, Vector, CV_8UC1};
use opencv::prelude::*;
use opencv::{imgproc, video};
use rand::{Rng, SeedableRng};
use std::path::Path;

/// Features per key frame.
const MAX_FEATURES: i32 = 400;
/// Largest residual (processing pixels) of an inlier of the fit.
const INLIER_PX: f64 = 1.0;
/// Cells (x, y) over which the features of a key frame are spread.
const BUCKETS: (usize, usize) = (8, 6);
/// Fewest inliers of a registered frame.
pub(super) const MIN_INLIERS: usize = 12;
/// RANSAC samples per frame.
const SAMPLES: usize = 120;
/// Lucas–Kanade window (processing pixels) and pyramid levels above the frame. 15 rather than
/// OpenCV's customary 21: fewer of a feature's window pixels are animals, and LK costs less
/// (RESULTS.md §2 has the table at 21 and 15, BENCHMARKS.md "Extraction throughput" the time).
const LK_WIN: i32 = 15;
const LK_LEVELS: i32 = 3;

/// A key frame: its grey image's pyramid and features (processing pixels), its camera (key frame →
/// reference frame, processing pixels) and how many features it started with.
struct Key {
    /// The grey's LK pyramid with its derivatives, built once for every frame registered on it
    /// (what `calc_optical_flow_pyr_lk` would otherwise rebuild from `grey` each time).
    pyr: Vector<Mat>,
    pts: Vec<[f64; 2]>,
    cam: Similarity,
    start: usize,
}

impl Key {
    fn new(grey: Mat, cam: Similarity, path: &Path) -> Result<Key> {
        let fail = cv(path);
        let (w, h) = (grey.cols(), grey.rows());
        // Features away from the border (a moving camera's frames may be padded there).
        let (mx, my) = ((w / 25).max(2), (h / 25).max(2));
        let mut mask =
            Mat::new_rows_cols_with_default(h, w, CV_8UC1, Scalar::all(0.0)).map_err(&fail)?;
        imgproc::rectangle(
            &mut mask,
            opencv::core::Rect::new(mx, my, w - 2 * mx, h - 2 * my),
            Scalar::all(255.0),
            -1,
            imgproc::LINE_8,
            0,
        )
        .map_err(&fail)?;
        // Many candidates, then at most MAX_FEATURES / 48 of the strongest in each cell of an
        // 8 × 6 grid: features spread over the whole ground rather than crowding on the
        // high-contrast animals (which move coherently and would outvote the ground).
        let mut corners = Vector::<Point2f>::new();
        imgproc::good_features_to_track(
            &grey,
            &mut corners,
            MAX_FEATURES * 8,
            0.001,
            5.0,
            &mask,
            3,
            false,
            0.04,
        )
        .map_err(&fail)?;
        let per_cell = (MAX_FEATURES as usize).div_ceil(BUCKETS.0 * BUCKETS.1);
        let mut filled = vec![0usize; BUCKETS.0 * BUCKETS.1];
        let mut pts = Vec::new();
        // Corners come strongest first.
        for p in corners.iter() {
            let bx = ((p.x as f64 / w as f64 * BUCKETS.0 as f64) as usize).min(BUCKETS.0 - 1);
            let by = ((p.y as f64 / h as f64 * BUCKETS.1 as f64) as usize).min(BUCKETS.1 - 1);
            let b = &mut filled[by * BUCKETS.0 + bx];
            if *b < per_cell {
                *b += 1;
                pts.push([p.x as f64, p.y as f64]);
            }
        }
        let mut pyr = Vector::<Mat>::new();
        video::build_optical_flow_pyramid(
            &grey,
            &mut pyr,
            Size::new(LK_WIN, LK_WIN),
            LK_LEVELS,
            true,
            opencv::core::BORDER_REFLECT_101,
            opencv::core::BORDER_CONSTANT,
            true,
        )
        .map_err(&fail)?;
        Ok(Key {
            pyr,
            start: pts.len(),
            pts,
            cam,
        })
    }
}

/// Evidence that the camera does not move, gathered while registering, for when registration
/// fails on a nearly textureless ground (GFTT then finds sensor noise and RANSAC no consensus,
/// issue #16): every 1/24th frame, slightly blurred, agrees with the per-pixel median of those
/// frames everywhere but on the animals. A moving camera over a textured ground, or a cut to
/// another view, disagrees over much of the frame; over a ground without texture the motion
/// cannot be seen, and a static camera is then the only reading the video supports.
struct Stillness {
    every: usize,
    frames: Vec<Vec<u8>>,
}

/// Grey levels (after the blur, beyond the frame's common brightness change) by which a pixel
/// differs from the median for it to count as changed.
const STILL_GREY: i16 = 12;
/// Largest fraction of changed pixels in a still frame: the animals and their old places in the
/// median (a herd may cover a large part of the frame; an 8-fish tank covers under 1 %).
const STILL_FRACTION: f64 = 0.05;
/// Gaussian blur (processing pixels) of the compared frames: sensor noise and MJPG blocks out.
const STILL_BLUR_PX: f64 = 1.5;

impl Stillness {
    fn new(total: usize) -> Stillness {
        Stillness {
            every: (total / 24).max(1),
            frames: Vec::new(),
        }
    }

    /// Keeps frame `i` (grey, processing pixels), blurred, when it is a sampled one.
    fn add(&mut self, i: usize, grey: &Mat, path: &Path) -> Result<()> {
        if i % self.every != 0 {
            return Ok(());
        }
        let mut f = Mat::default();
        imgproc::gaussian_blur_def(grey, &mut f, Size::new(0, 0), STILL_BLUR_PX)
            .map_err(cv(path))?;
        self.frames.push(f.data_bytes().map_err(cv(path))?.to_vec());
        Ok(())
    }

    /// The largest fraction of pixels of a sampled frame that differ from the samples' median
    /// (after removing the frame's median difference: a light that dims is not a moving camera).
    fn changed_fraction(&self) -> f64 {
        let n = self.frames.len();
        let Some(len) = self.frames.first().map(Vec::len) else {
            return 1.0;
        };
        let mut col = vec![0u8; n];
        let median: Vec<u8> = (0..len)
            .map(|p| {
                for (c, f) in col.iter_mut().zip(&self.frames) {
                    *c = f[p];
                }
                col.sort_unstable();
                col[n / 2]
            })
            .collect();
        let mut worst: f64 = 0.0;
        let mut hist = [0usize; 511];
        for f in &self.frames {
            hist.fill(0);
            for (&a, &m) in f.iter().zip(&median) {
                hist[(a as i16 - m as i16 + 255) as usize] += 1;
            }
            // The frame's median difference (its brightness change).
            let (mut acc, mut off) = (0usize, 0i16);
            for (k, &c) in hist.iter().enumerate() {
                acc += c;
                if acc * 2 >= len {
                    off = k as i16 - 255;
                    break;
                }
            }
            let changed: usize = hist
                .iter()
                .enumerate()
                .filter(|(k, _)| (*k as i16 - 255 - off).abs() > STILL_GREY)
                .map(|(_, &c)| c)
                .sum();
            worst = worst.max(changed as f64 / len as f64);
        }
        worst
    }

    /// Whether the camera is still by [`Stillness::changed_fraction`] (at least 3 samples).
    fn is_still(&self) -> bool {
        self.frames.len() >= 3 && self.changed_fraction() < STILL_FRACTION
    }
}

/// `a ∘ b`: first `b`, then `a`.
fn compose(a: &Similarity, b: &Similarity) -> Similarity {
    Similarity {
        scale: a.scale * b.scale,
        angle: a.angle + b.angle,
        t: a.apply(b.t),
    }
}

/// The similarity of two point pairs (exact), or none when the points coincide.
fn fit2(from: [[f64; 2]; 2], to: [[f64; 2]; 2]) -> Option<Similarity> {
    let d = [from[1][0] - from[0][0], from[1][1] - from[0][1]];
    if d[0].hypot(d[1]) < 1.0 {
        return None;
    }
    Some(Similarity::fit(&from, &to))
}

/// RANSAC over the pairs `from[i] → to[i]`: the similarity with most inliers (residual ≤
/// [`INLIER_PX`]) refitted on them, and the inliers; `seed` fixes the samples.
fn ransac(from: &[[f64; 2]], to: &[[f64; 2]], seed: u64) -> Option<(Similarity, Vec<bool>)> {
    let n = from.len();
    if n < 2 {
        return None;
    }
    let count = |v: &[bool]| v.iter().filter(|&&b| b).count();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut best: Option<(usize, Similarity)> = None;
    for _ in 0..SAMPLES {
        let i = rng.gen_range(0..n);
        let j = rng.gen_range(0..n);
        if i == j {
            continue;
        }
        let Some(s) = fit2([from[i], from[j]], [to[i], to[j]]) else {
            continue;
        };
        if !(0.5..2.0).contains(&s.scale) {
            continue;
        }
        let k = count_inliers(from, to, &s, INLIER_PX);
        if best.as_ref().is_none_or(|b| k > b.0) {
            best = Some((k, s));
        }
    }
    let (_, s) = best?;
    // Refit on the inliers at tightening residuals (1, 0.6, 0.35 px) while at least half of
    // them remain: an animal that has moved only a fraction of a pixel from its key frame does
    // not pull the fit.
    let mut fit = s;
    let n1 = count_inliers(from, to, &fit, INLIER_PX);
    for tol in [INLIER_PX, 0.6, 0.35] {
        let keep = inliers_at(from, to, &fit, tol);
        if count(&keep) < MIN_INLIERS.max(n1 / 2) {
            break;
        }
        let (f, t): (Vec<_>, Vec<_>) = from
            .iter()
            .zip(to)
            .zip(&keep)
            .filter(|(_, &k)| k)
            .map(|((p, q), _)| (*p, *q))
            .unzip();
        fit = Similarity::fit(&f, &t);
    }
    Some((fit, inliers_at(from, to, &fit, INLIER_PX)))
}

/// Whether `fit` maps `p` to within `tol` pixels of `q`.
fn within(map: &impl Fn([f64; 2]) -> [f64; 2], p: [f64; 2], q: [f64; 2], tol: f64) -> bool {
    let r = map(p);
    (r[0] - q[0]).hypot(r[1] - q[1]) <= tol
}

/// Which pairs `fit` maps to within `tol` pixels.
fn inliers_at(from: &[[f64; 2]], to: &[[f64; 2]], fit: &Similarity, tol: f64) -> Vec<bool> {
    let map = fit.mapper();
    from.iter()
        .zip(to)
        .map(|(p, q)| within(&map, *p, *q, tol))
        .collect()
}

/// How many pairs `fit` maps to within `tol` pixels.
fn count_inliers(from: &[[f64; 2]], to: &[[f64; 2]], fit: &Similarity, tol: f64) -> usize {
    let map = fit.mapper();
    from.iter()
        .zip(to)
        .filter(|(p, q)| within(&map, **p, **q, tol))
        .count()
}

/// Registers `grey` against `key` starting from the previous frame's camera `prev` (processing
/// pixels): the frame's camera and every key feature's residual, or none when fewer than
/// [`MIN_INLIERS`] features agree (or fewer than a fifth of those tracked).
fn register(
    key: &Key,
    grey: &Mat,
    prev: &Similarity,
    seed: u64,
    path: &Path,
) -> Result<Option<(Similarity, Vec<f64>)>> {
    let fail = cv(path);
    if key.pts.len() < MIN_INLIERS {
        return Ok(None);
    }
    let to_frame = prev.inverse();
    let src: Vector<Point2f> = key
        .pts
        .iter()
        .map(|p| Point2f::new(p[0] as f32, p[1] as f32))
        .collect();
    let mut dst: Vector<Point2f> = key
        .pts
        .iter()
        .map(|p| {
            let q = to_frame.apply(key.cam.apply(*p));
            Point2f::new(q[0] as f32, q[1] as f32)
        })
        .collect();
    let (mut status, mut err) = (Vector::<u8>::new(), Vector::<f32>::new());
    let crit = TermCriteria::new(
        opencv::core::TermCriteria_COUNT | opencv::core::TermCriteria_EPS,
        30,
        0.01,
    )
    .map_err(&fail)?;
    let t_lk = profile::start();
    video::calc_optical_flow_pyr_lk(
        &key.pyr,
        grey,
        &src,
        &mut dst,
        &mut status,
        &mut err,
        Size::new(LK_WIN, LK_WIN),
        LK_LEVELS,
        crit,
        video::OPTFLOW_USE_INITIAL_FLOW,
        1e-4,
    )
    .map_err(&fail)?;
    profile::stop("A LK", t_lk);
    let t_ransac = profile::start();
    let (w, h) = (grey.cols() as f64, grey.rows() as f64);
    let mut idx = Vec::new();
    let (mut from, mut to) = (Vec::new(), Vec::new());
    for (i, (s, d)) in status.iter().zip(dst.iter()).enumerate() {
        let d = [d.x as f64, d.y as f64];
        if s == 1 && d[0] >= 0.0 && d[1] >= 0.0 && d[0] < w && d[1] < h {
            idx.push(i);
            from.push(d);
            to.push(key.pts[i]);
        }
    }
    let fit = ransac(&from, &to, seed);
    profile::stop("A RANSAC", t_ransac);
    let Some((s, keep)) = fit else {
        return Ok(None);
    };
    let n_in = keep.iter().filter(|&&k| k).count();
    if n_in < MIN_INLIERS || n_in * 5 < from.len() {
        return Ok(None);
    }
    // Every key feature's residual under the fit (infinite where it was lost).
    let mut resid = vec![f64::INFINITY; key.pts.len()];
    for (k, &i) in idx.iter().enumerate() {
        let r = s.apply(from[k]);
        resid[i] = (r[0] - to[k][0]).hypot(r[1] - to[k][1]);
    }
    Ok(Some((compose(&key.cam, &s), resid)))
}

/// Frame indices as ranges ("3–7, 12").
fn ranges(frames: &[usize]) -> String {
    let mut out: Vec<String> = Vec::new();
    let mut i = 0;
    while i < frames.len() {
        let mut j = i;
        while j + 1 < frames.len() && frames[j + 1] == frames[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            frames[i].to_string()
        } else {
            format!("{}–{}", frames[i], frames[j])
        });
        i = j + 1;
    }
    out.join(", ")
}

/// Pass A without anchors: the raw camera (frame → first frame, video pixels) of every frame in
/// `first..last`, registered on the background's features (module docs). A second thread decodes
/// and converts frames to grey at the processing resolution. Frames that cannot be registered
/// are an error naming them. The full-resolution frames `keep` names (indices within the range,
/// ascending) are returned with the path.
pub(super) fn camera_path(
    vid: &mut Video,
    path: &Path,
    cfg: &ExtractConfig,
    (first, last): (usize, usize),
    keep: &[usize],
    progress: &mut impl FnMut(&str, usize, usize),
) -> Result<(Vec<Similarity>, Kept)> {
    let (w, h) = (vid.w, vid.h);
    let scale = (cfg.max_side as f64 / w.max(h) as f64).min(1.0);
    let total = vid.count.saturating_sub(first).min(last - first);
    let mut raw: Vec<Similarity> = Vec::new();
    let mut failed = Vec::new();
    let mut key: Option<Key> = None;
    let mut last_good: Option<(Mat, Similarity)> = None;
    let mut stillness = Stillness::new(total);
    let mut kept = Vec::new();
    let debug = std::env::var_os("HERDFIT_DEBUG").is_some();
    let (tx, rx) = std::sync::mpsc::sync_channel::<Result<(Mat, Option<Mat>)>>(4);
    std::thread::scope(|scope| -> Result<()> {
        let producer = scope.spawn(move || {
            let mut k = 0usize;
            while first + k < last {
                let item = (|| -> Result<Option<(Mat, Option<Mat>)>> {
                    let Some(frame) = profile::time("A decode", || vid.next())? else {
                        return Ok(None);
                    };
                    let t = profile::start();
                    // Grey first: the area average then runs over one channel, not three.
                    let mut full = Mat::default();
                    imgproc::cvt_color(&frame, &mut full, imgproc::COLOR_BGR2GRAY, 0)
                        .map_err(cv(path))?;
                    let grey = downscaled(&full, scale, path)?;
                    profile::stop("A downscale + grey", t);
                    Ok(Some((
                        grey,
                        keep.binary_search(&k).is_ok().then_some(frame),
                    )))
                })();
                if !forward(&tx, item) {
                    return;
                }
                k += 1;
            }
        });
        while let Ok(item) = profile::time("A wait for frame", || rx.recv()) {
            let (grey, full) = item?;
            let i = raw.len();
            if let Some(f) = full {
                kept.push((i, f));
            }
            profile::time("A stillness sample", || stillness.add(i, &grey, path))?;
            match &mut key {
                None => {
                    key = Some(profile::time("A key frame (GFTT)", || {
                        Key::new(grey, Similarity::IDENTITY, path)
                    })?);
                    raw.push(Similarity::IDENTITY);
                }
                Some(k) => {
                    let prev = *raw.last().unwrap_or(&Similarity::IDENTITY);
                    let mut got =
                        profile::time("A register", || register(k, &grey, &prev, i as u64, path))?;
                    if got.is_none() {
                        // The key frame has worn out: start one on the last registered frame
                        // and try again.
                        if let Some((g, c)) = last_good.take() {
                            *k = Key::new(g, c, path)?;
                            got = register(k, &grey, &prev, i as u64, path)?;
                        }
                    }
                    if debug {
                        eprintln!(
                            "register {}: {} key features of {}, {}",
                            first + i,
                            k.pts.len(),
                            k.start,
                            if got.is_some() { "ok" } else { "failed" }
                        );
                    }
                    match got {
                        Some((cam, _)) => {
                            raw.push(cam);
                            last_good = Some((grey, cam));
                        }
                        None => {
                            failed.push(first + i);
                            raw.push(prev);
                        }
                    }
                }
            }
            progress("stabilise", raw.len(), total);
        }
        drop(rx);
        let _ = producer.join();
        Ok(())
    })?;
    if debug {
        eprintln!(
            "register: largest fraction of changed pixels in {} samples against their median: \
             {:.4}",
            stillness.frames.len(),
            stillness.changed_fraction()
        );
    }
    let textureless = key.as_ref().is_some_and(|k| k.start < MIN_INLIERS) && raw.len() > 1;
    if (textureless || !failed.is_empty()) && stillness.is_still() {
        // Nothing to register on, but the frames do not change: a static camera.
        return Ok((vec![Similarity::IDENTITY; raw.len()], kept));
    }
    if let Some(k) = &key {
        if k.start < MIN_INLIERS && raw.len() > 1 {
            return Err(Error::file(
                path,
                format!(
                    "cannot stabilise: the first frame has only {} trackable features (a \
                     video without texture?); give --static-camera or --anchor rectangles",
                    k.start
                ),
            ));
        }
    }
    if !failed.is_empty() {
        return Err(Error::file(
            path,
            format!(
                "the camera moves too much to register frames {} (fewer than {MIN_INLIERS} \
                 background features agree with one similarity); give --anchor rectangles, or \
                 --frames to leave them out",
                ranges(&failed)
            ),
        ));
    }
    // Processing pixels → video pixels: the same rotation and zoom, the translation / scale.
    let raw = raw
        .into_iter()
        .map(|s| Similarity {
            t: [s.t[0] / scale, s.t[1] / scale],
            ..s
        })
        .collect();
    Ok((raw, kept))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ransac_recovers_a_similarity_among_outliers() {
        let truth = Similarity {
            scale: 1.1,
            angle: 0.2,
            t: [5.0, -3.0],
        };
        let mut from = Vec::new();
        let mut to = Vec::new();
        for k in 0..60 {
            let p = [(k * 37 % 200) as f64, (k * 53 % 150) as f64];
            from.push(p);
            // A third of the points move on their own (animals).
            to.push(if k % 3 == 0 {
                [p[0] + 9.0, p[1] - 4.0]
            } else {
                truth.apply(p)
            });
        }
        let (s, keep) = ransac(&from, &to, 1).unwrap();
        assert!((s.scale - 1.1).abs() < 1e-9 && (s.angle - 0.2).abs() < 1e-9);
        assert!((s.t[0] - 5.0).abs() < 1e-6 && (s.t[1] + 3.0).abs() < 1e-6);
        assert_eq!(keep.iter().filter(|&&k| k).count(), 40);
        let c = compose(&s, &s.inverse());
        assert!((c.scale - 1.0).abs() < 1e-12 && c.t[0].abs() < 1e-9);
        assert_eq!(ranges(&[1, 2, 3, 7, 9, 10]), "1–3, 7, 9–10");
    }
}
