//! Top-view renders of a crowd: a PNG of one frame with trails (plotters) and, with the `video`
//! feature, an MJPG AVI of the whole run (OpenCV). Agents are coloured by behaviour; walls are
//! black, obstacles grey, pivots red, behaviour regions outlined.

use super::features::V2;
use super::layout::Layout;
use crate::data::tracks::Tracks;
use crate::error::Result;
use plotters::prelude::*;
use std::collections::BTreeMap;
use std::path::Path;

/// Colour of a behaviour (RGB).
pub fn behaviour_colour(role: Option<&str>) -> (u8, u8, u8) {
    match role {
        Some("interaction") => (214, 39, 40),
        Some("line") => (44, 160, 44),
        Some("real") => (120, 120, 120),
        _ => (31, 119, 180),
    }
}

/// The extent to draw: the layout's bounds, else the tracks' with a 5% margin.
pub fn extent(tracks: &[&Tracks], layout: Option<&Layout>) -> [V2; 2] {
    if let Some(b) = layout.and_then(|l| l.bounds) {
        return b;
    }
    let mut b = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
    for r in tracks.iter().flat_map(|t| &t.rows) {
        for (a, &v) in r.pos.iter().take(2).enumerate() {
            b[0][a] = b[0][a].min(v);
            b[1][a] = b[1][a].max(v);
        }
    }
    if !b[0][0].is_finite() {
        return [[0.0, 0.0], [1.0, 1.0]];
    }
    let m = 0.05 * (b[1][0] - b[0][0]).max(b[1][1] - b[0][1]).max(1e-6);
    [[b[0][0] - m, b[0][1] - m], [b[1][0] + m, b[1][1] + m]]
}

/// Positions per id over frames `from..=to`, each with its role at that frame.
fn trails(t: &Tracks, from: u64, to: u64) -> BTreeMap<u64, Vec<(V2, Option<String>)>> {
    let mut m: BTreeMap<u64, Vec<(V2, Option<String>)>> = BTreeMap::new();
    for r in t.rows.iter().filter(|r| r.frame >= from && r.frame <= to) {
        m.entry(r.id)
            .or_default()
            .push(([r.pos[0], r.pos[1]], r.role.clone()));
    }
    m
}

/// A PNG top view at `frame` with `trail` frames of history per agent. `overlay` tracks (e.g. the
/// real ones) are drawn in grey beneath.
pub fn top_view_png(
    path: &Path,
    title: &str,
    tracks: &Tracks,
    overlay: Option<&Tracks>,
    layout: Option<&Layout>,
    frame: u64,
    trail: u64,
) -> Result<()> {
    let b = extent(&[tracks], layout);
    let (w, h) = (b[1][0] - b[0][0], b[1][1] - b[0][1]);
    let wpx = 1000u32;
    let hpx = ((wpx as f64 - 80.0) * h / w + 90.0).clamp(240.0, 1400.0) as u32;
    let unit = tracks.meta.units.as_str();
    crate::plot::png(path, (wpx, hpx), |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(40)
            .build_cartesian_2d(b[0][0]..b[1][0], b[0][1]..b[1][1])?;
        chart
            .configure_mesh()
            .disable_mesh()
            .x_desc(format!("x ({unit})"))
            .y_desc(format!("y ({unit})"))
            .label_style(("sans-serif", 12))
            .draw()?;
        if let Some(l) = layout {
            for o in &l.obstacles {
                chart.draw_series(std::iter::once(Polygon::new(
                    o.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
                    RGBColor(150, 150, 150).filled(),
                )))?;
            }
            for r in &l.regions {
                let mut pts: Vec<(f64, f64)> = r.polygon.iter().map(|p| (p[0], p[1])).collect();
                pts.push(pts[0]);
                let (cr, cg, cb) = behaviour_colour(Some(&r.behaviour));
                chart.draw_series(std::iter::once(PathElement::new(pts, RGBColor(cr, cg, cb))))?;
            }
            for wl in &l.walls {
                chart.draw_series(std::iter::once(PathElement::new(
                    wl.iter().map(|p| (p[0], p[1])).collect::<Vec<_>>(),
                    BLACK.stroke_width(3),
                )))?;
            }
            for p in &l.pivots {
                chart.draw_series(std::iter::once(TriangleMarker::new(
                    (p.position[0], p.position[1]),
                    8,
                    RED.filled(),
                )))?;
            }
        }
        let from = frame.saturating_sub(trail);
        if let Some(o) = overlay {
            for pts in trails(o, from, frame).values() {
                chart.draw_series(std::iter::once(PathElement::new(
                    pts.iter().map(|(p, _)| (p[0], p[1])).collect::<Vec<_>>(),
                    RGBColor(190, 190, 190),
                )))?;
            }
        }
        for pts in trails(tracks, from, frame).values() {
            let (cr, cg, cb) = behaviour_colour(pts.last().and_then(|p| p.1.as_deref()));
            let c = RGBColor(cr, cg, cb);
            chart.draw_series(std::iter::once(PathElement::new(
                pts.iter().map(|(p, _)| (p[0], p[1])).collect::<Vec<_>>(),
                c.mix(0.5),
            )))?;
        }
        chart.draw_series(tracks.rows.iter().filter(|r| r.frame == frame).map(|r| {
            let (cr, cg, cb) = behaviour_colour(r.role.as_deref());
            Circle::new((r.pos[0], r.pos[1]), 4, RGBColor(cr, cg, cb).filled())
        }))?;
        Ok(())
    })
}

/// An MJPG AVI of every frame (agents as discs with short trails), `px` pixels per unit.
#[cfg(feature = "video")]
pub fn top_view_avi(path: &Path, tracks: &Tracks, layout: Option<&Layout>, px: f64) -> Result<()> {
    use crate::error::Error;
    use opencv::core::{Mat, Point, Scalar, CV_8UC3};
    use opencv::imgproc;
    let cv = |e: opencv::Error| Error::file(path, format!("OpenCV: {}", e.message));
    let b = extent(&[tracks], layout);
    let even = |v: f64| ((v * px).ceil() as usize).div_ceil(2) as i32 * 2;
    let (w, h) = (
        even(b[1][0] - b[0][0]).max(2),
        even(b[1][1] - b[0][1]).max(2),
    );
    if (w as i64) * (h as i64) > 4096 * 4096 {
        return Err(Error::invalid(format!(
            "a {w}×{h} video frame is too large"
        )));
    }
    let to_px = |p: V2| {
        Point::new(
            ((p[0] - b[0][0]) * px).round() as i32,
            (h as f64 - (p[1] - b[0][1]) * px).round() as i32,
        )
    };
    let fps = tracks.meta.fps.clamp(1.0, 60.0);
    let mut writer = crate::video::AviWriter::create(path, fps, w, h)?;
    let bgr = |c: (u8, u8, u8)| Scalar::new(c.2 as f64, c.1 as f64, c.0 as f64, 0.0);
    let mut base =
        Mat::new_rows_cols_with_default(h, w, CV_8UC3, Scalar::all(245.0)).map_err(cv)?;
    if let Some(l) = layout {
        for o in &l.obstacles {
            let pts: opencv::core::Vector<Point> = o.iter().map(|p| to_px(*p)).collect();
            imgproc::fill_poly_def(&mut base, &pts, Scalar::all(150.0)).map_err(cv)?;
        }
        for wl in &l.walls {
            for s in wl.windows(2) {
                imgproc::line(
                    &mut base,
                    to_px(s[0]),
                    to_px(s[1]),
                    Scalar::all(0.0),
                    3,
                    imgproc::LINE_AA,
                    0,
                )
                .map_err(cv)?;
            }
        }
    }
    let radius = ((0.2 * px).round() as i32).max(2);
    for (f, range) in tracks.frames() {
        let mut img = base.clone();
        for (_, pts) in trails(tracks, f.saturating_sub(8), f) {
            let c = bgr(behaviour_colour(pts.last().and_then(|p| p.1.as_deref())));
            for s in pts.windows(2) {
                imgproc::line(
                    &mut img,
                    to_px(s[0].0),
                    to_px(s[1].0),
                    c,
                    1,
                    imgproc::LINE_AA,
                    0,
                )
                .map_err(cv)?;
            }
        }
        for r in &tracks.rows[range] {
            let c = bgr(behaviour_colour(r.role.as_deref()));
            imgproc::circle(
                &mut img,
                to_px([r.pos[0], r.pos[1]]),
                radius,
                c,
                -1,
                imgproc::LINE_AA,
                0,
            )
            .map_err(cv)?;
        }
        writer.write(&img)?;
    }
    writer.commit()
}
