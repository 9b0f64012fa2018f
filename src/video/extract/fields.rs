//! Pass C of an extraction: segmentation of every stabilised frame against the background (and
//! the body colour), Farneback optical flow on the stabilised greys, and the per-cell sums they
//! give — herd pixels, flow, direction variance — turned into density (herd pixels / body pixels
//! / cell area), velocity (flow averaged over the smoothing window, BL/s, y up) and direction
//! variance (paper §4, §6.2).

use super::background::{CellGrid, Geometry};
use super::blobs::blobs;
use super::camera::Similarity;
use super::decode::{cv, forward, Video};
use super::preview::preview_png;
use super::profile;
use super::ExtractConfig;
use crate::error::Result;
use ndarray::{Array3, Array4};
use opencv::core::{Mat, Point, Scalar, Size};
use opencv::prelude::*;
use opencv::{imgproc, video};

/// One frame through segmentation: the stabilised frame, its herd mask (255 = herd) and grey.
type Stage = (Mat, Vec<u8>, Mat);

/// Per-frame, per-cell accumulations of pass C, and the previews.
pub(super) struct Sums {
    /// Herd pixels.
    pub count: Vec<Vec<f64>>,
    /// Summed flow of herd pixels (BL/s, y up).
    pub fsum: Vec<Vec<[f64; 2]>>,
    /// Mean squared angle between each herd pixel's flow and its cell's mean flow (rad²).
    pub var: Vec<Vec<f64>>,
    /// Speed of every herd pixel with a flow (BL/s).
    pub speeds: Vec<f64>,
    /// First frame with a flow (frame 0 has none).
    first_flow: Option<usize>,
    pub previews: Vec<(String, Vec<u8>)>,
}

/// The largest per-channel difference between the BGR pixel `p` of `px` and of `bg`.
pub(super) fn difference(px: &[u8], bg: &[u8], p: usize) -> u8 {
    (0..3)
        .map(|c| px[p * 3 + c].abs_diff(bg[p * 3 + c]))
        .max()
        .unwrap_or(0)
}

/// What segmentation needs, built once: the background, the threshold on the difference to it,
/// the optional colour test, a morphological opening for wide bodies and the smallest component
/// kept (smaller ones are compression specks, not animals).
pub(super) struct Segmenter<'a> {
    geom: &'a Geometry<'a>,
    background: &'a [u8],
    threshold: f64,
    colour: Option<([u8; 3], f64)>,
    /// Morphological opening of the mask (when a body is ≥ 6 processing pixels wide).
    morph: bool,
    /// Components smaller than this (processing pixels) are dropped.
    min_area: usize,
    ones: Mat,
    kernel: Mat,
}

impl<'a> Segmenter<'a> {
    pub fn new(
        geom: &'a Geometry<'a>,
        background: &'a [u8],
        cfg: &ExtractConfig,
        threshold: f64,
        morph: bool,
        min_area: usize,
    ) -> Result<Self> {
        let kernel = imgproc::get_structuring_element(
            imgproc::MORPH_ELLIPSE,
            Size::new(3, 3),
            Point::new(-1, -1),
        )
        .map_err(cv(geom.path))?;
        Ok(Segmenter {
            geom,
            background,
            threshold,
            colour: cfg.body_colour.map(|c| (c, cfg.colour_threshold)),
            morph,
            min_area,
            ones: geom.ones()?,
            kernel,
        })
    }

    /// The herd mask (255 = herd) of the stabilised BGR frame `px` with valid pixels `vm`.
    pub fn mask(&self, px: &[u8], vm: &[u8]) -> Result<Vec<u8>> {
        let fail = cv(self.geom.path);
        let mut herd = vec![0u8; self.geom.pw * self.geom.ph];
        for p in 0..self.geom.pw * self.geom.ph {
            if vm[p] == 0 {
                continue;
            }
            let mut on = difference(px, self.background, p) as f64 > self.threshold;
            if let Some((c, t)) = self.colour {
                let (b, g, r) = (px[p * 3] as f64, px[p * 3 + 1] as f64, px[p * 3 + 2] as f64);
                let dist = ((r - c[0] as f64).powi(2)
                    + (g - c[1] as f64).powi(2)
                    + (b - c[2] as f64).powi(2))
                .sqrt();
                on = on && dist < t;
            }
            herd[p] = if on { 255 } else { 0 };
        }
        if self.morph {
            let m = Mat::from_slice(&herd)
                .map_err(&fail)?
                .reshape(1, self.geom.ph as i32)
                .map_err(&fail)?
                .try_clone()
                .map_err(&fail)?;
            let mut o = Mat::default();
            imgproc::morphology_ex(
                &m,
                &mut o,
                imgproc::MORPH_OPEN,
                &self.kernel,
                Point::new(-1, -1),
                1,
                opencv::core::BORDER_CONSTANT,
                Scalar::all(0.0),
            )
            .map_err(&fail)?;
            herd.copy_from_slice(o.data_bytes().map_err(&fail)?);
        }
        if self.min_area > 1 {
            blobs(&mut herd, self.geom.pw, self.min_area, true);
        }
        Ok(herd)
    }

    /// Stabilises frame `f` by the camera `cam`, segments it and converts it to grey.
    fn frame(&self, f: &Mat, cam: &Similarity) -> Result<Stage> {
        let fail = cv(self.geom.path);
        let (mut st, mut valid) = (Mat::default(), Mat::default());
        let t = profile::start();
        self.geom.warp(f, cam, &mut st, imgproc::INTER_LINEAR)?;
        self.geom
            .warp(&self.ones, cam, &mut valid, imgproc::INTER_NEAREST)?;
        profile::stop("C warp", t);
        let t = profile::start();
        let herd = self.mask(
            st.data_bytes().map_err(&fail)?,
            valid.data_bytes().map_err(&fail)?,
        )?;
        profile::stop("C mask", t);
        let mut grey = Mat::default();
        imgproc::cvt_color(&st, &mut grey, imgproc::COLOR_BGR2GRAY, 0).map_err(&fail)?;
        Ok((st, herd, grey))
    }
}

/// Two threads computing the Farneback flow of consecutive stabilised greys, frame `i`'s (from
/// frame `i − 1`) on thread `i % 2`: the flows are the same whichever thread runs them.
struct FlowWorkers {
    jobs: [std::sync::mpsc::SyncSender<(Mat, Mat)>; 2],
    results: [std::sync::mpsc::Receiver<Result<Mat>>; 2],
}

impl FlowWorkers {
    fn start<'scope>(
        scope: &'scope std::thread::Scope<'scope, '_>,
        path: &'scope std::path::Path,
    ) -> FlowWorkers {
        let worker = || {
            let (job_tx, job_rx) = std::sync::mpsc::sync_channel::<(Mat, Mat)>(1);
            let (res_tx, res_rx) = std::sync::mpsc::sync_channel::<Result<Mat>>(1);
            scope.spawn(move || {
                for (pg, grey) in job_rx {
                    let mut flow = Mat::default();
                    let r = profile::time("C Farneback", || {
                        video::calc_optical_flow_farneback(
                            &pg, &grey, &mut flow, 0.5, 2, 13, 2, 5, 1.1, 0,
                        )
                    });
                    if res_tx.send(r.map(|_| flow).map_err(cv(path))).is_err() {
                        return;
                    }
                }
            });
            (job_tx, res_rx)
        };
        let (a, b) = (worker(), worker());
        FlowWorkers {
            jobs: [a.0, b.0],
            results: [a.1, b.1],
        }
    }

    /// Starts frame `i`'s flow from the previous grey `pg` to `grey`.
    fn send(&self, i: usize, pg: Mat, grey: Mat) -> Result<()> {
        self.jobs[i % 2]
            .send((pg, grey))
            .map_err(|_| crate::error::Error::Internal("a flow thread ended".into()))
    }

    /// Frame `i`'s flow (the flows of one thread arrive in the order they were sent).
    fn recv(&self, i: usize) -> Result<Mat> {
        self.results[i % 2]
            .recv()
            .map_err(|_| crate::error::Error::Internal("a flow thread ended".into()))?
    }
}

/// Pass C over the `frames` frames from `first`: a thread decodes, stabilises and segments frames,
/// two more compute the optical flows of alternate frame pairs, and this one accumulates the
/// cells in frame order. One preview every `preview_every` frames when given.
#[allow(clippy::too_many_arguments)]
pub(super) fn pass_c(
    vid: &mut Video,
    geom: &Geometry,
    grid: &CellGrid,
    seg: &Segmenter,
    body_length_px: f64,
    camera: &[Similarity],
    (first, frames): (usize, usize),
    preview_every: Option<usize>,
    progress: &mut impl FnMut(&str, usize, usize),
) -> Result<Sums> {
    let (path, scale) = (geom.path, geom.scale);
    let to_bl_s = vid.fps / (body_length_px * scale);
    vid.rewind()?;
    vid.skip(first)?;
    let cells = grid.cells();
    let mut sums = Sums {
        count: vec![vec![0.0f64; cells]; frames],
        fsum: vec![vec![[0.0f64; 2]; cells]; frames],
        var: vec![vec![0.0f64; cells]; frames],
        speeds: Vec::new(),
        first_flow: None,
        previews: Vec::new(),
    };
    let mut prev_grey: Option<Mat> = None;
    std::thread::scope(|scope| -> Result<()> {
        let (tx, rx) = std::sync::mpsc::sync_channel::<Result<Stage>>(4);
        let producer = {
            let tx = tx.clone();
            let vid = &mut *vid;
            scope.spawn(move || {
                for cam in camera.iter() {
                    let item = (|| -> Result<Option<Stage>> {
                        let Some(f) = profile::time("C decode", || vid.next())? else {
                            return Ok(None);
                        };
                        seg.frame(&f, cam).map(Some)
                    })();
                    if !forward(&tx, item) {
                        return;
                    }
                }
            })
        };
        drop(tx);
        let flows = FlowWorkers::start(scope, path);
        // Frames whose flow is being computed: (index, stabilised frame, herd mask, has a flow).
        let mut pending = std::collections::VecDeque::new();
        type Pending = (usize, Mat, Vec<u8>, bool);
        let mut finish = |sums: &mut Sums, (j, st, herd, flowing): Pending| -> Result<()> {
            if flowing {
                let flow = profile::time("C wait for flow", || flows.recv(j))?;
                profile::time("C flow sums", || {
                    sums.flow(j, &flow, &herd, grid, to_bl_s, path)
                })?;
            }
            if let Some(every) = preview_every {
                if j % every.max(1) == 0 {
                    let png = preview_png(&st, &herd, &sums.count[j], &sums.fsum[j], grid, geom)?;
                    sums.previews.push((format!("preview-{j:05}.png"), png));
                }
            }
            progress("fields", j + 1, frames);
            Ok(())
        };
        for i in 0..frames {
            let Ok(item) = profile::time("C wait for frame", || rx.recv()) else {
                break;
            };
            let (st, herd, grey) = item?;
            sums.count[i] = grid.herd_pixels(&herd);
            let flowing = match prev_grey.take() {
                Some(pg) => {
                    flows.send(i, pg, grey.try_clone().map_err(cv(path))?)?;
                    true
                }
                None => false,
            };
            prev_grey = Some(grey);
            pending.push_back((i, st, herd, flowing));
            // At most one flow in progress on each worker.
            while pending.len() > 2 || pending.front().is_some_and(|p| !p.3) {
                if let Some(p) = pending.pop_front() {
                    finish(&mut sums, p)?;
                }
            }
        }
        while let Some(p) = pending.pop_front() {
            finish(&mut sums, p)?;
        }
        drop(rx);
        let _ = producer.join();
        Ok(())
    })?;
    // Frame 0 has no previous frame: it takes frame 1's flow.
    if let Some(k) = sums.first_flow {
        let (a, b) = (sums.fsum[k].clone(), sums.var[k].clone());
        for i in 0..k {
            sums.fsum[i] = a.clone();
            sums.var[i] = b.clone();
        }
    }
    Ok(sums)
}

/// The fields of an extraction from its sums.
pub(super) struct Fields {
    pub density: Array3<f32>,
    pub velocity: Array4<f32>,
    pub dir_variance: Array3<f32>,
    /// `(density, speed, agents)` of every occupied cell and frame, for the speed–density table.
    pub samples: Vec<(f64, f64, f64)>,
    /// Mean and standard deviation of the herd pixels' speeds (BL/s).
    pub speed: (f64, f64),
}

impl Sums {
    /// The sums of a still (one frame, no flow): herd pixels per cell, and in every cell that
    /// holds herd pixels the direction variance (rad²) its animals have when their directions
    /// spread by `dir_variance` (`per_animal` herd pixels to an animal;
    /// [`crate::measure::dir_variance::SampleVariance`]).
    pub fn still(count: Vec<f64>, dir_variance: f64, per_animal: f64) -> Sums {
        let expected = crate::measure::dir_variance::SampleVariance::new(dir_variance);
        let var = count
            .iter()
            .map(|&n| match n > 0.0 {
                true => expected.at(n / per_animal.max(f64::MIN_POSITIVE)),
                false => 0.0,
            })
            .collect();
        Sums {
            fsum: vec![vec![[0.0; 2]; count.len()]],
            var: vec![var],
            count: vec![count],
            speeds: Vec::new(),
            first_flow: None,
            previews: Vec::new(),
        }
    }

    /// Frame `i`'s flow `flow` (Farneback, from the previous grey): summed per cell over herd
    /// pixels (BL/s, y up), the pixels' speeds, and each cell's direction variance about its mean
    /// flow.
    fn flow(
        &mut self,
        i: usize,
        flow: &Mat,
        herd: &[u8],
        grid: &CellGrid,
        to_bl_s: f64,
        path: &std::path::Path,
    ) -> Result<()> {
        let fail = cv(path);
        let fl: &[opencv::core::Vec2f] = flow.data_typed().map_err(&fail)?;
        let mut sum = vec![[0.0f64; 2]; grid.cells()];
        for p in 0..grid.cell_of.len() {
            if herd[p] > 0 {
                let c = grid.cell_of[p] as usize;
                let v = [fl[p][0] as f64 * to_bl_s, -(fl[p][1] as f64) * to_bl_s];
                sum[c][0] += v[0];
                sum[c][1] += v[1];
                self.speeds.push((v[0] * v[0] + v[1] * v[1]).sqrt());
            }
        }
        // Direction variance about each cell's mean flow direction.
        let mut sq = vec![0.0f64; grid.cells()];
        let mut n = vec![0.0f64; grid.cells()];
        for p in 0..grid.cell_of.len() {
            if herd[p] > 0 {
                let c = grid.cell_of[p] as usize;
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
        for c in 0..grid.cells() {
            if n[c] > 0.0 {
                self.var[i][c] = sq[c] / n[c];
            }
        }
        self.fsum[i] = sum;
        self.first_flow.get_or_insert(i);
        Ok(())
    }

    /// Density (herd pixels / body pixels per animal / cell area, agents/BL²), velocity (flow
    /// sums over the smoothing window / herd pixels in it) and direction variance of every cell
    /// and frame; `body_px_proc` is the body pixels per animal at the processing resolution.
    pub fn fields(
        &self,
        grid: &CellGrid,
        smooth: usize,
        body_length_px: f64,
        body_px_proc: f64,
    ) -> Fields {
        let frames = self.count.len();
        let half = smooth / 2;
        let area_bl = (grid.cell_px / body_length_px).powi(2);
        let mut density = Array3::<f32>::zeros((frames, grid.ny, grid.nx));
        let mut velocity = Array4::<f32>::zeros((frames, grid.ny, grid.nx, 2));
        let mut dir_variance = Array3::<f32>::zeros((frames, grid.ny, grid.nx));
        let mut samples = Vec::new();
        for i in 0..frames {
            let (lo, hi) = (i.saturating_sub(half), (i + half + 1).min(frames));
            for c in 0..grid.cells() {
                let (iy, ix) = (c / grid.nx, c % grid.nx);
                let n = self.count[i][c];
                if n <= 0.0 {
                    continue;
                }
                let agents = n / body_px_proc;
                let rho = agents / area_bl;
                density[[i, iy, ix]] = rho as f32;
                let (mut s, mut k) = ([0.0; 2], 0.0);
                for j in lo..hi {
                    s[0] += self.fsum[j][c][0];
                    s[1] += self.fsum[j][c][1];
                    k += self.count[j][c];
                }
                if k > 0.0 {
                    let v = [s[0] / k, s[1] / k];
                    velocity[[i, iy, ix, 0]] = v[0] as f32;
                    velocity[[i, iy, ix, 1]] = v[1] as f32;
                    samples.push((rho, (v[0] * v[0] + v[1] * v[1]).sqrt(), agents));
                }
                dir_variance[[i, iy, ix]] = self.var[i][c] as f32;
            }
        }
        let (mean, std_bp) = if self.speeds.is_empty() {
            (0.0, 0.0)
        } else {
            let m = self.speeds.iter().sum::<f64>() / self.speeds.len() as f64;
            let v =
                self.speeds.iter().map(|s| (s - m).powi(2)).sum::<f64>() / self.speeds.len() as f64;
            (m, v.sqrt())
        };
        Fields {
            density,
            velocity,
            dir_variance,
            samples,
            speed: (mean, std_bp),
        }
    }
}
