//! Automatic calibration of an extraction (paper §4): the foreground threshold on the difference
//! to the background, the body length L in pixels and the body pixels per animal N_bp, each
//! estimated from the sampled stabilised frames of the background unless the settings give it.
//!
//! - Threshold: Otsu's split of the histogram of the per-pixel difference d = max over channels
//!   |frame − background|, taken above the noise floor (median of d + 4 robust σ, at least
//!   [`MIN_THRESHOLD`]) so that a herd covering 1 % of the frame is not split inside the noise.
//! - Body size: connected components of the herd mask (8-connected) over the sampled frames; the
//!   single animals are the mode of the distribution of log-area (a kernel density, bandwidth
//!   0.12): isolated animals all have nearly the same area while merged groups spread over 2, 3,
//!   … times it. N_bp is the median area of the components within ×0.7–1.4 of the mode; L is the
//!   median full major axis 4 √λ₁ of their second moments (exact for a filled ellipse). When
//!   the mode is at the smallest components looked at, or its components hold under 10 % of the
//!   herd pixels (fragments of badly contrasted bodies, ground texture: OpenCV's `vtest.avi`),
//!   the components around the area-weighted median are taken (`body_size.rs`).
//! - Or from a user count: N_bp = herd pixels of one frame / the animals counted on it.

use super::background::{Geometry, Sample};
use super::blobs::{blobs, Blob, MIN_COMPONENT};
use super::body_size::body_size;
use super::fields::{difference, Segmenter};
use super::profile;
use super::{ExtractConfig, UserCount, AUTO_CELL_BL};
use crate::data::clip::BODY_WIDTH_BL;
use crate::error::{Error, Result};
use serde::Serialize;

/// The calibration an extraction ran with: each value and where it came from ("given" or how it
/// was estimated); recorded in `clip.json` under `provenance.calibration`.
#[derive(Clone, Debug, Serialize)]
pub struct Calibration {
    /// Threshold on the difference to the background (grey levels).
    pub threshold: f64,
    pub threshold_from: String,
    /// Threshold of the body-length estimate: half the herd's contrast.
    pub length_threshold: f64,
    /// Body length L (video pixels).
    pub body_length_px: f64,
    pub body_length_from: String,
    /// Body pixels per animal N_bp (video pixels).
    pub body_pixels: f64,
    pub body_pixels_from: String,
    /// Cells along the longer side.
    pub grid: usize,
    pub grid_from: String,
    /// Components taken as single animals (0 when N_bp and L were given).
    pub isolated_animals: usize,
    /// Components of the sampled frames' herd masks.
    pub components: usize,
    /// Whether the mask is opened (bodies ≥ 6 processing pixels wide).
    pub opening: bool,
    /// Smallest component kept (processing pixels).
    pub min_component_px: usize,
    /// How the camera was found: "anchors", "registered" or "static".
    pub camera: String,
    /// With anchors: the largest distance (video pixels) at a frame corner between the anchors'
    /// camera path and the automatic registration's, or why the registration failed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub registration_vs_anchors_px: Option<serde_json::Value>,
    /// Area of every component of the sampled frames (video pixels), for the report.
    #[serde(skip)]
    pub areas: Vec<f64>,
}

impl Calibration {
    /// The segmenter of the fields: this calibration's threshold, opening and smallest
    /// component.
    pub(super) fn segmenter<'a>(
        &self,
        geom: &'a Geometry<'a>,
        background: &'a [u8],
        cfg: &ExtractConfig,
    ) -> Result<Segmenter<'a>> {
        Segmenter::new(
            geom,
            background,
            cfg,
            self.threshold,
            self.opening,
            self.min_component_px,
        )
    }
}

/// `f` of every sampled frame, in the sample's order: the first half of the frames on this
/// thread, the second on another.
fn per_frame<T: Send>(
    sample: &Sample,
    f: impl Fn(&(usize, Vec<u8>, Vec<u8>)) -> T + Sync,
) -> Vec<T> {
    let (a, b) = sample.frames.split_at(sample.frames.len() / 2);
    let f = &f;
    std::thread::scope(|scope| {
        let second = scope.spawn(move || b.iter().map(f).collect::<Vec<T>>());
        let mut out: Vec<T> = a.iter().map(f).collect();
        match second.join() {
            Ok(v) => out.extend(v),
            Err(e) => std::panic::resume_unwind(e),
        }
        out
    })
}

/// Herd masks of the sampled frames under `seg`, and their components.
fn sample_blobs(seg: &Segmenter, sample: &Sample, w: usize) -> Result<Vec<Blob>> {
    let per = per_frame(sample, |(_, px, vm)| -> Result<Vec<Blob>> {
        let mut m = seg.mask(px, vm)?;
        Ok(blobs(&mut m, w, MIN_COMPONENT, false))
    });
    let mut all = Vec::new();
    for b in per {
        all.extend(b?);
    }
    Ok(all)
}

/// The calibration of an extraction from its background `bg` and `sample` (module docs); `count`
/// is the index within the sample's range of the frame of `cfg.count`.
pub(super) fn calibrate(
    cfg: &ExtractConfig,
    geom: &Geometry,
    bg: &[u8],
    sample: &Sample,
    count: Option<usize>,
) -> Result<Calibration> {
    let (pw, scale) = (geom.pw, geom.scale);
    let path = geom.path;
    let t = profile::start();
    let (threshold, threshold_from) = match cfg.background_threshold {
        Some(t) => (t, "given".to_string()),
        None => {
            let mut hist = [0u64; 256];
            let per = per_frame(sample, |(_, px, vm)| {
                let mut h = [0u64; 256];
                for p in 0..geom.pw * geom.ph {
                    if vm[p] > 0 {
                        h[difference(px, bg, p) as usize] += 1;
                    }
                }
                h
            });
            for h in per {
                hist.iter_mut().zip(h).for_each(|(a, b)| *a += b);
            }
            let t = threshold(&hist).ok_or_else(|| {
                Error::file(
                    path,
                    format!(
                        "no animals found: no pixel of the {} sampled frames differs from the \
                         background by more than the noise (a video of one colour?)",
                        sample.frames.len()
                    ),
                )
            })?;
            (t, "Otsu above the noise floor".to_string())
        }
    };
    profile::stop("K Otsu", t);
    let t = profile::start();
    // Stage 1: the mask at half the herd's contrast (the 90th percentile of the difference of
    // herd pixels) gives the body's length and width — where a blurred edge crosses half its
    // contrast is the true edge — and so whether to open the mask.
    let raw = Segmenter::new(geom, bg, cfg, threshold, false, 1)?;
    let per = per_frame(sample, |(_, px, vm)| -> Result<Vec<u8>> {
        let m = raw.mask(px, vm)?;
        Ok(m.iter()
            .enumerate()
            .filter(|(_, &v)| v > 0)
            .map(|(p, _)| difference(px, bg, p))
            .collect())
    });
    let mut diffs = Vec::new();
    for d in per {
        diffs.extend(d?);
    }
    diffs.sort_unstable();
    let contrast = diffs.get(diffs.len() * 9 / 10).map_or(0.0, |&v| v as f64);
    let length_threshold = threshold.max(contrast / 2.0);
    profile::stop("K contrast masks", t);
    let raw = Segmenter::new(geom, bg, cfg, length_threshold, false, 1)?;
    let first = profile::time("K length masks + blobs", || sample_blobs(&raw, sample, pw))?;
    let no_animals = || {
        Error::file(
            path,
            format!(
                "no animals found: nothing in the {} sampled frames stands out of the background \
                 by more than {threshold} grey levels",
                sample.frames.len()
            ),
        )
    };
    let size1 = profile::time("K length mode (KDE)", || body_size(&first));
    let (body_length_px, body_length_from, opening) = match (cfg.body_length_px, size1) {
        (Some(l), _) => (l, "given".to_string(), l * BODY_WIDTH_BL * scale >= 6.0),
        (None, Some(size)) => (
            size.blob.major / scale,
            format!("median major axis of {}", size.what()),
            size.blob.minor >= 6.0,
        ),
        (None, None) => return Err(no_animals()),
    };
    // Stage 2: the mask as the fields see it gives N_bp.
    let seg = Segmenter::new(geom, bg, cfg, threshold, opening, 1)?;
    let comps = profile::time("K N_bp masks + blobs", || sample_blobs(&seg, sample, pw))?;
    let size2 = profile::time("K N_bp mode (KDE)", || body_size(&comps));
    let (body_pixels, body_pixels_from, isolated) = match (cfg.body_pixels, &cfg.count, size2) {
        (Some(n), _, _) => (n, "given".to_string(), 0),
        (None, Some(c), _) => {
            let k = count.and_then(|i| sample.frames.iter().find(|f| f.0 == i));
            let Some((_, px, vm)) = k else {
                return Err(Error::config(
                    "count",
                    format!("frame {} is not in the video", c.frame),
                ));
            };
            let mut m = seg.mask(px, vm)?;
            blobs(&mut m, pw, MIN_COMPONENT, true);
            let on = m.iter().filter(|&&v| v > 0).count() as f64;
            (
                from_count(on, c)? / (scale * scale),
                format!("{} animals counted on frame {}", c.animals, c.frame),
                0,
            )
        }
        (None, None, Some(size)) => (
            size.blob.area / (scale * scale),
            format!("median area of {}", size.what()),
            size.n,
        ),
        (None, None, None) => return Err(no_animals()),
    };
    let longer = geom.w.max(geom.h) as f64;
    let (grid, grid_from) = match cfg.grid {
        Some(g) => (g, "given".to_string()),
        None => (
            ((longer / (AUTO_CELL_BL * body_length_px)).round() as usize).clamp(1, 4096),
            format!("cells of {AUTO_CELL_BL} body lengths"),
        ),
    };
    crate::limits::check_grid("grid", grid, grid)?;
    let min_component_px =
        ((0.2 * body_pixels * scale * scale).floor() as usize).max(MIN_COMPONENT);
    Ok(Calibration {
        threshold,
        threshold_from,
        length_threshold,
        body_length_px,
        body_length_from,
        body_pixels,
        body_pixels_from,
        grid,
        grid_from,
        isolated_animals: isolated,
        components: comps.len(),
        opening,
        min_component_px,
        camera: String::new(),
        registration_vs_anchors_px: None,
        areas: comps.iter().map(|b| b.area / (scale * scale)).collect(),
    })
}

/// Smallest automatic threshold (grey levels): below it lies compression noise.
pub(super) const MIN_THRESHOLD: f64 = 10.0;

/// Otsu's threshold of the difference histogram `hist` (256 bins) above its noise floor; `None`
/// when nothing in the frames stands out of the background.
pub(super) fn threshold(hist: &[u64; 256]) -> Option<f64> {
    let total: u64 = hist.iter().sum();
    if total == 0 {
        return None;
    }
    let quantile = |q: f64| {
        let target = (q * total as f64).ceil() as u64;
        let mut acc = 0;
        for (v, &c) in hist.iter().enumerate() {
            acc += c;
            if acc >= target.max(1) {
                return v as f64;
            }
        }
        255.0
    };
    let med = quantile(0.5);
    // Robust σ from the median absolute deviation (the background is most of the frame).
    let mut dev = [0u64; 256];
    for (v, &c) in hist.iter().enumerate() {
        dev[(v as f64 - med).abs() as usize] += c;
    }
    let mut acc = 0;
    let mut mad = 0.0;
    for (v, &c) in dev.iter().enumerate() {
        acc += c;
        if acc * 2 >= total {
            mad = v as f64;
            break;
        }
    }
    let floor = (med + 4.0 * 1.4826 * mad.max(1.0)).max(MIN_THRESHOLD);
    let (n, sum): (f64, f64) = hist.iter().enumerate().fold((0.0, 0.0), |(n, s), (v, &c)| {
        (n + c as f64, s + v as f64 * c as f64)
    });
    if hist[(floor.ceil() as usize).min(255)..]
        .iter()
        .all(|&c| c == 0)
    {
        return None;
    }
    // Otsu over the whole histogram: the split maximising the between-class variance, the middle
    // of the run of splits that tie (an empty gap between background and herd).
    let (mut w0, mut s0, mut best) = (0.0, 0.0, -1.0);
    let (mut first, mut last) = (0usize, 0usize);
    for (v, &c) in hist.iter().enumerate().take(255) {
        w0 += c as f64;
        s0 += v as f64 * c as f64;
        let w1 = n - w0;
        if w0 == 0.0 || w1 == 0.0 {
            continue;
        }
        let (m0, m1) = (s0 / w0, (sum - s0) / w1);
        let between = w0 * w1 * (m0 - m1).powi(2);
        if between > best * (1.0 + 1e-12) {
            best = between;
            (first, last) = (v, v);
        } else if between >= best * (1.0 - 1e-12) && last + 1 == v {
            last = v;
        }
    }
    let t = (first + last) as f64 / 2.0 + 0.5;
    Some(t.max(floor))
}

/// N_bp from a user count: `pixels` herd pixels on the counted frame.
pub(super) fn from_count(pixels: f64, count: &UserCount) -> Result<f64> {
    if pixels <= 0.0 {
        return Err(Error::config(
            "count",
            format!(
                "frame {} has no herd pixels to divide among {} animals",
                count.frame, count.animals
            ),
        ));
    }
    Ok(pixels / count.animals as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ellipse_blob_has_its_axes() {
        // A filled ellipse of full axes 40 × 12 pixels.
        let (w, h) = (80, 40);
        let mut m = vec![0u8; w * h];
        for y in 0..h {
            for x in 0..w {
                let (u, v) = (
                    (x as f64 + 0.5 - 40.0) / 20.0,
                    (y as f64 + 0.5 - 20.0) / 6.0,
                );
                if u * u + v * v <= 1.0 {
                    m[y * w + x] = 255;
                }
            }
        }
        let b = blobs(&mut m, w, 1, false);
        assert_eq!(b.len(), 1);
        // Pixel centres inside the ellipse: the rasterised outline loses up to about a pixel of
        // axis (measured: 39.50 × 12.16 px for 40 × 12).
        assert!((b[0].major - 40.0).abs() < 1.0, "{:?}", b[0]);
        assert!((b[0].minor - 12.0).abs() < 1.0, "{:?}", b[0]);
        assert!((b[0].area - std::f64::consts::PI * 20.0 * 6.0).abs() < 8.0);
    }

    #[test]
    fn small_components_are_removed_and_modes_found() {
        let w = 10;
        let mut m = vec![0u8; 100];
        m[0] = 255; // a speck
        for p in [44, 45, 54, 55] {
            m[p] = 255;
        }
        let b = blobs(&mut m, w, 2, true);
        assert_eq!(b.len(), 1);
        assert_eq!(m[0], 0);
        assert_eq!(m[44], 255);
        // Ten singles of ~100 px, three pairs, a triple: the singles win.
        let mut v: Vec<Blob> = (0..10)
            .map(|k| Blob {
                area: 95.0 + k as f64,
                major: 20.0,
                minor: 6.0,
            })
            .collect();
        for a in [200.0, 205.0, 190.0, 310.0] {
            v.push(Blob {
                area: a,
                major: 30.0,
                minor: 10.0,
            });
        }
        let size = body_size(&v).unwrap();
        let (b, n) = (size.blob, size.n);
        assert_eq!(n, 10);
        assert!(!size.weighted);
        assert!((size.share - 995.0 / 1900.0).abs() < 1e-12, "{size:?}");
        assert!((b.area - 100.0).abs() <= 1.0);
        assert_eq!((b.major, b.minor), (20.0, 6.0));
        // Two hundred fragments of 4–7 px around thirty walkers of ~600 px: the walkers hold
        // most of the pixels and win.
        let mut v: Vec<Blob> = (0..200)
            .map(|k| Blob {
                area: 4.0 + (k % 4) as f64,
                major: 3.0,
                minor: 1.5,
            })
            .collect();
        v.extend((0..30).map(|k| Blob {
            area: 585.0 + k as f64,
            major: 50.0,
            minor: 16.0,
        }));
        let size = body_size(&v).unwrap();
        let (b, n) = (size.blob, size.n);
        assert!(size.weighted);
        assert_eq!(n, 30);
        assert!((b.area - 600.0).abs() <= 1.0, "{b:?}");
        assert_eq!((b.major, b.minor), (50.0, 16.0));
    }

    #[test]
    fn otsu_splits_a_sparse_foreground_from_noise() {
        let mut hist = [0u64; 256];
        for (v, c) in [(0, 40_000), (1, 30_000), (2, 20_000), (3, 8_000), (4, 1000)] {
            hist[v] = c;
        }
        hist[60..120].fill(20);
        let t = threshold(&hist).unwrap();
        assert!((10.0..60.0).contains(&t), "{t}");
        assert_eq!(threshold(&[0u64; 256]), None);
    }
}
