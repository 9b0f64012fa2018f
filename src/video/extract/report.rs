//! `extract-report.png` of a clip folder: the calibration of an extraction on one page — the
//! histogram of the herd components' areas with the chosen body pixels per animal N_bp (§4), and
//! the camera path (eq. 1: translation, zoom and rotation of every frame onto the first).

use super::calibrate::Calibration;
use super::camera::Similarity;
use crate::error::{Error, Result};
use crate::plot::PALETTE;
use plotters::prelude::*;

const SIZE: (u32, u32) = (1200, 520);

/// The report as PNG bytes.
pub(super) fn report_png(calib: &Calibration, camera: &[Similarity]) -> Result<Vec<u8>> {
    crate::plot::font_ready()?;
    let fail = |e: String| Error::Internal(format!("drawing extract-report.png: {e}"));
    let mut rgb = vec![255u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
        root.fill(&WHITE).map_err(|e| fail(e.to_string()))?;
        let title = format!(
            "body length {:.1} px ({}); threshold {:.1} ({}); grid {} ({}); camera {}",
            calib.body_length_px,
            calib.body_length_from,
            calib.threshold,
            calib.threshold_from,
            calib.grid,
            calib.grid_from,
            calib.camera
        );
        let root = root
            .titled(&title, ("sans-serif", 15))
            .map_err(|e| fail(e.to_string()))?;
        let (left, right) = root.split_horizontally(SIZE.0 / 2);
        // Histogram of component areas up to 4 N_bp (larger ones in the last bin).
        let nbp = calib.body_pixels;
        let bins = 48usize;
        let top = 4.0 * nbp;
        let mut counts = vec![0u32; bins];
        for &a in &calib.areas {
            counts[((a / top * bins as f64) as usize).min(bins - 1)] += 1;
        }
        let ymax = counts.iter().copied().max().unwrap_or(1).max(1) as f64 * 1.1;
        let mut chart = ChartBuilder::on(&left)
            .caption(
                format!(
                    "{} components; N_bp = {:.1} px ({})",
                    calib.components, nbp, calib.body_pixels_from
                ),
                ("sans-serif", 14),
            )
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..top, 0.0..ymax)
            .map_err(|e| fail(e.to_string()))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("component area (video pixels; the last bin holds larger ones)")
            .y_desc("components")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        let bw = top / bins as f64;
        chart
            .draw_series(counts.iter().enumerate().map(|(k, &c)| {
                Rectangle::new(
                    [(k as f64 * bw, 0.0), ((k + 1) as f64 * bw, c as f64)],
                    PALETTE[0].mix(0.7).filled(),
                )
            }))
            .map_err(|e| fail(e.to_string()))?;
        chart
            .draw_series(std::iter::once(PathElement::new(
                vec![(nbp, 0.0), (nbp, ymax)],
                PALETTE[3].stroke_width(2),
            )))
            .map_err(|e| fail(e.to_string()))?;
        // Camera path.
        let series: [(&str, Vec<(f64, f64)>); 4] = [
            (
                "t_x (px)",
                camera
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (i as f64, c.t[0]))
                    .collect(),
            ),
            (
                "t_y (px)",
                camera
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (i as f64, c.t[1]))
                    .collect(),
            ),
            (
                "zoom − 1 (%)",
                camera
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (i as f64, (c.scale - 1.0) * 100.0))
                    .collect(),
            ),
            (
                "rotation (°)",
                camera
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (i as f64, c.angle.to_degrees()))
                    .collect(),
            ),
        ];
        let (lo, hi) = series
            .iter()
            .flat_map(|s| s.1.iter().map(|p| p.1))
            .fold((-1.0f64, 1.0f64), |(a, b), v| (a.min(v), b.max(v)));
        let mut chart = ChartBuilder::on(&right)
            .caption("camera: frame → first frame", ("sans-serif", 14))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(50)
            .build_cartesian_2d(0.0..(camera.len().max(2) - 1) as f64, lo * 1.1..hi * 1.1)
            .map_err(|e| fail(e.to_string()))?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc("frame")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(|e| fail(e.to_string()))?;
        for (k, (name, pts)) in series.into_iter().enumerate() {
            let c = PALETTE[k];
            chart
                .draw_series(LineSeries::new(pts, c.stroke_width(2)))
                .map_err(|e| fail(e.to_string()))?
                .label(name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
        }
        crate::plot::legend(&mut chart, 0.8, 12).map_err(|e| fail(e.to_string()))?;
        root.present().map_err(|e| fail(e.to_string()))?;
    }
    encode(&rgb)
}

/// RGB bytes of [`SIZE`] → PNG (OpenCV's encoder, which takes BGR).
fn encode(rgb: &[u8]) -> Result<Vec<u8>> {
    use opencv::prelude::*;
    let fail = |e: opencv::Error| Error::Internal(format!("encoding extract-report.png: {e}"));
    let mut m = opencv::core::Mat::new_rows_cols_with_default(
        SIZE.1 as i32,
        SIZE.0 as i32,
        opencv::core::CV_8UC3,
        opencv::core::Scalar::all(0.0),
    )
    .map_err(fail)?;
    {
        let data = m.data_bytes_mut().map_err(fail)?;
        for (d, s) in data.chunks_exact_mut(3).zip(rgb.chunks_exact(3)) {
            d.copy_from_slice(&[s[2], s[1], s[0]]);
        }
    }
    let mut buf = opencv::core::Vector::<u8>::new();
    opencv::imgcodecs::imencode(".png", &m, &mut buf, &opencv::core::Vector::new())
        .map_err(fail)?;
    Ok(buf.to_vec())
}
