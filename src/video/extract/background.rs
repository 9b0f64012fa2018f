//! The processing frame of an extraction: the stabilising warp at the processing resolution, the
//! background (a given image or the per-pixel median of sampled stabilised frames), the grid of
//! cells over the first frame and the obstacle cells of a mask image.

use super::camera::Similarity;
use super::decode::{cv, forward, Kept, Video};
use super::profile;
use super::ExtractConfig;
use crate::data::obstacle_polygons::ObstaclePolygons;
use crate::error::{Error, Result};
use ndarray::Array2;
use opencv::core::{Mat, Scalar, Size, CV_8UC1};
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc};
use std::path::Path;

/// The video's size and the processing resolution (the longer side at most `max_side` pixels).
pub(super) struct Geometry<'a> {
    pub path: &'a Path,
    pub w: usize,
    pub h: usize,
    /// Processing pixels per video pixel (≤ 1).
    pub scale: f64,
    pub pw: usize,
    pub ph: usize,
}

impl<'a> Geometry<'a> {
    pub fn new(path: &'a Path, w: usize, h: usize, max_side: usize) -> Self {
        let scale = (max_side as f64 / w.max(h) as f64).min(1.0);
        Geometry {
            path,
            w,
            h,
            scale,
            pw: ((w as f64) * scale).round() as usize,
            ph: ((h as f64) * scale).round() as usize,
        }
    }

    /// Warps frame `m` by the camera `s` into the first frame's view at the processing
    /// resolution.
    pub fn warp(&self, m: &Mat, s: &Similarity, out: &mut Mat, interp: i32) -> Result<()> {
        let scale = self.scale;
        let (c, sn) = (
            s.angle.cos() * s.scale * scale,
            s.angle.sin() * s.scale * scale,
        );
        let mm = Mat::from_slice_2d(&[[c, -sn, s.t[0] * scale], [sn, c, s.t[1] * scale]])
            .map_err(cv(self.path))?;
        imgproc::warp_affine(
            m,
            out,
            &mm,
            Size::new(self.pw as i32, self.ph as i32),
            interp,
            opencv::core::BORDER_CONSTANT,
            Scalar::all(0.0),
        )
        .map_err(cv(self.path))
    }

    /// The image `path` (read with OpenCV's `flags`), which must be the size of a video frame.
    pub fn image(&self, path: &Path, flags: i32) -> Result<Mat> {
        let img = imgcodecs::imread(path.as_os_str(), flags).map_err(cv(path))?;
        if img.empty() {
            return Err(Error::file(path, "cannot read as an image"));
        }
        let (w, h) = (self.w, self.h);
        if img.cols() as usize != w || img.rows() as usize != h {
            return Err(Error::file(
                path,
                format!("is {}×{}, the video is {w}×{h}", img.cols(), img.rows()),
            ));
        }
        Ok(img)
    }

    /// An all-255 mask the size of a video frame (warped to tell valid pixels).
    pub fn ones(&self) -> Result<Mat> {
        Mat::new_rows_cols_with_default(self.h as i32, self.w as i32, CV_8UC1, Scalar::all(255.0))
            .map_err(cv(self.path))
    }
}

/// Stabilised frames sampled over the range at the processing resolution: the background's
/// median and the calibration are taken from them.
pub(super) struct Sample {
    /// (frame index within the range, BGR bytes, valid-pixel mask: non-zero where the warped
    /// frame has data).
    pub frames: Vec<(usize, Vec<u8>, Vec<u8>)>,
}

/// Most bytes of full-resolution frames that pass A keeps for the background sample (so that
/// pass B need not decode the video again); a longer or larger sample is decoded again.
pub(super) const KEEP_BYTES: usize = 256 << 20;

/// The frames (indices within a range of `frames`) sampled for the background's median (up to 31,
/// evenly spread, first and last included), and all the sampled frames: those with frame `extra`
/// (the frame of a user count) when given, in frame order.
pub(super) fn sample_picks(frames: usize, extra: Option<usize>) -> (Vec<usize>, Vec<usize>) {
    let samples = frames.min(31);
    let median_of: Vec<usize> = (0..samples)
        .map(|k| k * frames.saturating_sub(1) / (samples.saturating_sub(1)).max(1))
        .collect();
    let mut pick = median_of.clone();
    pick.extend(extra);
    pick.sort_unstable();
    pick.dedup();
    (median_of, pick)
}

/// The background at the processing resolution (BGR bytes): `cfg.background`, or the per-pixel
/// median of up to 31 sampled stabilised frames of `first..first + frames`; and the sample
/// (which also holds frame `extra` of the range when given: the frame of a user count). `kept`:
/// the full-resolution frames of [`sample_picks`] that pass A kept, in order; when they are not
/// exactly those, the video is decoded again.
#[allow(clippy::too_many_arguments)]
pub(super) fn background(
    vid: &mut Video,
    geom: &Geometry,
    cfg: &ExtractConfig,
    camera: &[Similarity],
    (first, frames): (usize, usize),
    extra: Option<usize>,
    kept: Kept,
    progress: &mut impl FnMut(&str, usize, usize),
) -> Result<(Vec<u8>, Sample)> {
    let path = geom.path;
    let fail = cv(path);
    let (median_of, pick) = sample_picks(frames, extra);
    let mut sample = Sample {
        frames: Vec::with_capacity(pick.len()),
    };
    let ones = geom.ones()?;
    let warp = |i: usize, f: &Mat| -> Result<(usize, Vec<u8>, Vec<u8>)> {
        let t = profile::start();
        let (mut o, mut m) = (Mat::default(), Mat::default());
        geom.warp(f, &camera[i], &mut o, imgproc::INTER_LINEAR)?;
        geom.warp(&ones, &camera[i], &mut m, imgproc::INTER_NEAREST)?;
        let out = (
            i,
            o.data_bytes().map_err(&fail)?.to_vec(),
            m.data_bytes().map_err(&fail)?.to_vec(),
        );
        profile::stop("B warp sample", t);
        Ok(out)
    };
    if kept.iter().map(|k| k.0).eq(pick.iter().copied()) {
        for (n, (i, f)) in kept.iter().enumerate() {
            sample.frames.push(warp(*i, f)?);
            progress("background", n + 1, kept.len());
        }
    } else {
        drop(kept);
        vid.rewind()?;
        vid.skip(first)?;
        // A second thread decodes while this one warps the sampled frames.
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Mat>>(4);
        std::thread::scope(|scope| -> Result<()> {
            let producer = scope.spawn(move || {
                for _ in 0..camera.len() {
                    if !forward(&tx, profile::time("B decode", || vid.next())) {
                        return;
                    }
                }
            });
            for i in 0..camera.len() {
                let Ok(f) = rx.recv() else { break };
                let f = f?;
                if pick.contains(&i) {
                    sample.frames.push(warp(i, &f)?);
                }
                progress("background", i + 1, frames);
            }
            drop(rx);
            let _ = producer.join();
            Ok(())
        })?;
    }
    if let Some(bg) = &cfg.background {
        let img = geom.image(bg, imgcodecs::IMREAD_COLOR)?;
        let mut out = Mat::default();
        geom.warp(&img, &Similarity::IDENTITY, &mut out, imgproc::INTER_AREA)?;
        return Ok((out.data_bytes().map_err(cv(path))?.to_vec(), sample));
    }
    let stack: Vec<&(usize, Vec<u8>, Vec<u8>)> = sample
        .frames
        .iter()
        .filter(|(i, _, _)| median_of.contains(i))
        .collect();
    let t = profile::start();
    let bg = median(&stack, geom.pw * geom.ph);
    profile::stop("B median", t);
    Ok((bg, sample))
}

/// The per-pixel, per-channel median (the upper one of an even count) of the BGR frames of
/// `stack` over the pixels their masks mark valid (0 where none is), for `pixels` pixels; the
/// two halves of the frame on two threads.
fn median(stack: &[&(usize, Vec<u8>, Vec<u8>)], pixels: usize) -> Vec<u8> {
    let mut bg = vec![0u8; pixels * 3];
    let half = pixels / 2;
    let (lo, hi) = bg.split_at_mut(half * 3);
    let part = |out: &mut [u8], from: usize| {
        let mut vals = Vec::with_capacity(stack.len());
        for (k, px) in out.chunks_exact_mut(3).enumerate() {
            let p = from + k;
            for (c, o) in px.iter_mut().enumerate() {
                vals.clear();
                for (_, s, m) in stack {
                    if m[p] > 0 {
                        vals.push(s[p * 3 + c]);
                    }
                }
                if !vals.is_empty() {
                    let mid = vals.len() / 2;
                    *o = *vals.select_nth_unstable(mid).1;
                }
            }
        }
    };
    std::thread::scope(|scope| {
        scope.spawn(|| part(hi, half));
        part(lo, 0);
    });
    bg
}

/// The grid of an extraction: square cells of max(W, H) / N video pixels over the first frame,
/// `nx = ⌈W / cell⌉` by `ny = ⌈H / cell⌉`, row 0 at the bottom, and the cell of every processing
/// pixel.
pub(super) struct CellGrid {
    pub cell_px: f64,
    pub nx: usize,
    pub ny: usize,
    /// Cell index (row-major, row 0 at the bottom) of each processing pixel.
    pub cell_of: Vec<i32>,
}

impl CellGrid {
    pub fn new(geom: &Geometry, cells: usize) -> Self {
        let (w, h, scale, pw, ph) = (geom.w, geom.h, geom.scale, geom.pw, geom.ph);
        let cell_px = w.max(h) as f64 / cells as f64;
        let nx = (w as f64 / cell_px).ceil() as usize;
        let ny = (h as f64 / cell_px).ceil() as usize;
        let cell_of: Vec<i32> = (0..pw * ph)
            .map(|p| {
                let (u, v) = ((p % pw) as f64 + 0.5, (p / pw) as f64 + 0.5);
                let (x, y) = (u / scale, h as f64 - v / scale);
                let ix = ((x / cell_px) as usize).min(nx - 1);
                let iy = ((y.max(0.0) / cell_px) as usize).min(ny - 1);
                (iy * nx + ix) as i32
            })
            .collect();
        CellGrid {
            cell_px,
            nx,
            ny,
            cell_of,
        }
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.nx * self.ny
    }

    /// Herd pixels per cell of a processing-resolution mask (non-zero = herd).
    pub fn herd_pixels(&self, herd: &[u8]) -> Vec<f64> {
        let mut count = vec![0.0f64; self.cells()];
        for (&on, &c) in herd.iter().zip(&self.cell_of) {
            if on > 0 {
                count[c as usize] += 1.0;
            }
        }
        count
    }
}

/// Obstacle cells from `cfg.obstacles` (a mask image the size of the video frame, non-zero =
/// obstacle, or a `herdfit.obstacle-polygons/1` JSON file of polygons in video pixels painted
/// into such a mask): a cell is an obstacle when more than half its pixels are.
pub(super) fn obstacle_cells(
    cfg: &ExtractConfig,
    geom: &Geometry,
    grid: &CellGrid,
) -> Result<Array2<u8>> {
    let (w, h) = (geom.w, geom.h);
    let (cell_px, nx, ny, cells) = (grid.cell_px, grid.nx, grid.ny, grid.cells());
    let obstacles = match &cfg.obstacles {
        None => Array2::<u8>::zeros((ny, nx)),
        Some(mp) => {
            let painted;
            let img;
            let data: &[u8] = if mp
                .extension()
                .is_some_and(|e| e.eq_ignore_ascii_case("json"))
            {
                painted = ObstaclePolygons::load(mp)?.mask(w, h);
                &painted
            } else {
                img = geom.image(mp, imgcodecs::IMREAD_GRAYSCALE)?;
                img.data_bytes().map_err(cv(mp))?
            };
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
    Ok(obstacles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use opencv::videoio;

    #[test]
    fn sample_picks_spread_over_the_range_with_the_count_frame() {
        let (median_of, pick) = sample_picks(100, Some(50));
        assert_eq!(median_of.len(), 31);
        assert_eq!((median_of[0], median_of[30]), (0, 99));
        assert!(median_of.windows(2).all(|w| w[0] < w[1]));
        // Frame 50 is not among the 31 (k · 99 / 30), so the sample has 32 frames, in order.
        assert!(!median_of.contains(&50));
        assert_eq!(pick.len(), 32);
        assert!(pick.windows(2).all(|w| w[0] < w[1]) && pick.contains(&50));
        // A count frame that is sampled anyway is held once.
        let (_, pick) = sample_picks(10, Some(3));
        assert_eq!(pick, (0..10).collect::<Vec<_>>());
        assert_eq!(sample_picks(2, None).1, vec![0, 1]);
    }

    /// The frames pass A keeps give the same background and sample as decoding the video again.
    #[test]
    fn kept_frames_give_the_decoded_background() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("v.avi");
        let (w, h, n) = (96, 64, 40);
        let fourcc = videoio::VideoWriter::fourcc('M', 'J', 'P', 'G').unwrap();
        let mut out =
            videoio::VideoWriter::new(path.to_str().unwrap(), fourcc, 10.0, Size::new(w, h), true)
                .unwrap();
        for f in 0..n {
            let bytes: Vec<u8> = (0..w * h * 3)
                .map(|p| ((p * 7 + f * 13) % 251) as u8)
                .collect();
            let m = Mat::from_slice(&bytes).unwrap();
            out.write(&m.reshape(3, h).unwrap()).unwrap();
        }
        out.release().unwrap();
        let mut vid = super::super::decode::open(&path).unwrap();
        let geom = Geometry::new(&path, w as usize, h as usize, 48);
        let camera: Vec<Similarity> = (0..n)
            .map(|f| Similarity {
                scale: 1.0 + f as f64 * 0.01,
                angle: f as f64 * 0.01,
                t: [f as f64, -0.5 * f as f64],
            })
            .collect();
        let cfg = ExtractConfig::default();
        let frames = n as usize;
        let (_, pick) = sample_picks(frames, Some(5));
        let mut kept = Vec::new();
        for i in 0..frames {
            let f = vid.next().unwrap().unwrap();
            if pick.contains(&i) {
                kept.push((i, f));
            }
        }
        let mut none = |_: &str, _: usize, _: usize| {};
        let mut run = |kept: Kept| {
            background(
                &mut vid,
                &geom,
                &cfg,
                &camera,
                (0, frames),
                Some(5),
                kept,
                &mut none,
            )
            .unwrap()
        };
        // Kept frames, then none kept: the video is decoded again.
        let (bg_kept, s_kept) = run(kept);
        let (bg_read, s_read) = run(Vec::new());
        assert_eq!(bg_kept.len(), 48 * 32 * 3);
        assert_eq!(bg_kept, bg_read);
        assert_eq!(s_kept.frames, s_read.frames);
        assert_eq!(s_kept.frames.len(), pick.len());
    }
}
