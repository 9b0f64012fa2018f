//! The animation seen from above as an MJPG AVI (feature `video`): each bird a small swept-wing
//! glyph along its heading, the leader in red, over a sky gradient; the camera follows the
//! flock's centroid, flight direction up.

use super::animate::Animation;
use crate::error::{Error, Result};
use crate::progress::Progress;
use opencv::core::{Mat, Point, Scalar, Vector, CV_8UC3};
use opencv::imgproc;
use opencv::prelude::*;
use std::path::Path;

fn cv(path: &Path) -> impl Fn(opencv::Error) -> Error + '_ {
    move |e| Error::file(path, format!("OpenCV: {}", e.message))
}

/// Renders `anim` to `path` (written through a temporary sibling).
pub fn render(path: &Path, anim: &Animation, progress: &mut dyn Progress) -> Result<()> {
    let s0 = anim.report.config.px_per_wingspan;
    let centroids: Vec<[f64; 2]> = anim
        .frames
        .iter()
        .map(|f| {
            let n = f.len().max(1) as f64;
            [
                f.iter().map(|p| p[0]).sum::<f64>() / n,
                f.iter().map(|p| p[1]).sum::<f64>() / n,
            ]
        })
        .collect();
    let mut ext: [f64; 2] = [4.0, 4.0];
    for (f, c) in anim.frames.iter().zip(&centroids) {
        for p in f {
            ext[0] = ext[0].max((p[0] - c[0]).abs());
            ext[1] = ext[1].max((p[1] - c[1]).abs());
        }
    }
    let even = |v: f64| ((v.ceil() as usize).div_ceil(2) * 2).max(64);
    let s = s0
        .min(1800.0 / (2.0 * ext[0] + 4.0))
        .min(1000.0 / (2.0 * ext[1] + 4.0));
    let (w, h) = (
        even((2.0 * ext[0] + 4.0) * s),
        even((2.0 * ext[1] + 4.0) * s),
    );
    let mut writer = crate::video::AviWriter::create(path, anim.report.fps, w as i32, h as i32)?;
    // Sky: light blue at the top to paler at the bottom (BGR).
    let mut sky = Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC3, Scalar::all(0.0))
        .map_err(cv(path))?;
    {
        let data = sky.data_bytes_mut().map_err(cv(path))?;
        for y in 0..h {
            let t = y as f64 / h as f64;
            let px = [
                (235.0 - 10.0 * t) as u8,
                (200.0 + 25.0 * t) as u8,
                (150.0 + 60.0 * t) as u8,
            ];
            for x in 0..w {
                data[(y * w + x) * 3..(y * w + x) * 3 + 3].copy_from_slice(&px);
            }
        }
    }
    progress.start("video", anim.frames.len() as u64);
    let mut frame = Mat::default();
    let leader_of = |f: &[[f64; 2]]| {
        (0..f.len())
            .max_by(|&a, &b| f[a][1].total_cmp(&f[b][1]))
            .unwrap_or(0)
    };
    for (k, (f, hd)) in anim.frames.iter().zip(&anim.headings).enumerate() {
        sky.copy_to(&mut frame).map_err(cv(path))?;
        let c = centroids[k];
        let to_px = |p: [f64; 2]| {
            Point::new(
                (w as f64 / 2.0 + (p[0] - c[0]) * s).round() as i32,
                (h as f64 / 2.0 - (p[1] - c[1]) * s).round() as i32,
            )
        };
        let lead = leader_of(f);
        for (i, (p, d)) in f.iter().zip(hd).enumerate() {
            let r = [d[1], -d[0]];
            let at =
                |a: f64, b: f64| to_px([p[0] + a * d[0] + b * r[0], p[1] + a * d[1] + b * r[1]]);
            let poly: Vector<Point> = Vector::from_iter([
                at(0.2, 0.0),
                at(-0.15, 0.5),
                at(-0.05, 0.0),
                at(-0.15, -0.5),
            ]);
            let colour = if i == lead {
                Scalar::new(40.0, 40.0, 200.0, 0.0)
            } else {
                Scalar::new(50.0, 50.0, 50.0, 0.0)
            };
            let polys: Vector<Vector<Point>> = Vector::from_iter([poly]);
            imgproc::fill_poly(
                &mut frame,
                &polys,
                colour,
                imgproc::LINE_AA,
                0,
                Point::new(0, 0),
            )
            .map_err(cv(path))?;
        }
        writer.write(&frame)?;
        progress.inc(1);
    }
    let video = writer.finish()?;
    progress.finish();
    video.commit()
}
