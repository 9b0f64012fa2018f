//! PNG plots (plotters, bitmap backend). Text uses DejaVu Sans from the system
//! (`fonts-dejavu-core`), registered once.

use crate::error::{Error, Result};
use plotters::coord::types::RangedCoordf64;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use std::path::Path;
use std::sync::OnceLock;

/// The series colours of every chart (matplotlib's tab10, first six).
pub const PALETTE: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

const FONT_PATHS: [&str; 2] = [
    "/usr/share/fonts/truetype/dejavu/DejaVuSans.ttf",
    "/usr/share/fonts/dejavu/DejaVuSans.ttf",
];

pub(crate) fn font_ready() -> Result<()> {
    static READY: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    READY
        .get_or_init(|| {
            let bytes = FONT_PATHS
                .iter()
                .find_map(|p| std::fs::read(p).ok())
                .ok_or_else(|| {
                    "DejaVuSans.ttf not found (install fonts-dejavu-core)".to_string()
                })?;
            let bytes: &'static [u8] = Box::leak(bytes.into_boxed_slice());
            plotters::style::register_font("sans-serif", FontStyle::Normal, bytes)
                .map_err(|_| "DejaVuSans.ttf is not a usable font".to_string())
        })
        .clone()
        .map_err(Error::invalid)
}

/// A chart on `root` captioned `caption` in sans-serif of `font` px, with `margin` px and label
/// areas of (x, y) px.
fn builder<'a, 'b, DB: DrawingBackend>(
    root: &'a DrawingArea<DB, plotters::coord::Shift>,
    caption: &str,
    font: i32,
    margin: u32,
    (x, y): (u32, u32),
) -> ChartBuilder<'a, 'b, DB> {
    let mut b = ChartBuilder::on(root);
    b.caption(caption, ("sans-serif", font))
        .margin(margin)
        .x_label_area_size(x)
        .y_label_area_size(y);
    b
}

/// What a drawing closure of [`png`] returns: any plotting error, as text for the message.
pub(crate) type Drawn = std::result::Result<(), Box<dyn std::error::Error>>;

/// The drawing area of a PNG being drawn by [`png`].
pub(crate) type Area<'a> = DrawingArea<BitMapBackend<'a>, Shift>;

/// Draws a `size` bitmap with `draw` and writes it atomically as the PNG `path` (the font
/// registered first; a drawing error names the file: "plotting: …").
pub(crate) fn png(path: &Path, size: (u32, u32), draw: impl FnOnce(&Area) -> Drawn) -> Result<()> {
    font_ready().map_err(|e| e.in_file(path))?;
    let tmp = crate::data::atomic::temp_sibling(path, ".png")?;
    let fail = |e: Box<dyn std::error::Error>| Error::file(path, format!("plotting: {e}"));
    {
        let root = BitMapBackend::new(tmp.path(), size).into_drawing_area();
        draw(&root).map_err(fail)?;
        root.present().map_err(|e| fail(e.into()))?;
    }
    crate::data::atomic::persist(tmp, path)
}

type Chart2d<'a, DB> = ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>;
type DrawResult<DB> =
    std::result::Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Axes with a mesh, labelled `x` and `y` in `font` px.
pub(crate) fn axes<DB: DrawingBackend>(
    chart: &mut Chart2d<DB>,
    x: &str,
    y: &str,
    font: i32,
) -> DrawResult<DB> {
    chart
        .configure_mesh()
        .x_desc(x)
        .y_desc(y)
        .label_style(("sans-serif", font))
        .draw()
}

/// Axes without a mesh, labelled `x` and `y` in 12 px.
fn bare_axes<DB: DrawingBackend>(chart: &mut Chart2d<DB>, x: &str, y: &str) -> DrawResult<DB> {
    chart
        .configure_mesh()
        .disable_mesh()
        .x_desc(x)
        .y_desc(y)
        .label_style(("sans-serif", 12))
        .draw()
}

/// The chart's legend: its series labels on white of opacity `opacity`, a black border, text in
/// `font` px.
pub(crate) fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    opacity: f64,
    font: i32,
) -> DrawResult<DB> {
    chart
        .configure_series_labels()
        .background_style(WHITE.mix(opacity))
        .border_style(BLACK)
        .label_font(("sans-serif", font))
        .draw()
}

/// The bounding box (x0, x1, y0, y1) of the finite points, or the unit square when there are
/// none.
fn extent(points: impl Iterator<Item = (f64, f64)>) -> (f64, f64, f64, f64) {
    let (mut x0, mut x1, mut y0, mut y1) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    for (x, y) in points.filter(|p| p.0.is_finite() && p.1.is_finite()) {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if !x0.is_finite() {
        return (0.0, 1.0, 0.0, 1.0);
    }
    (x0, x1, y0, y1)
}

/// One named series of (x, y) points.
pub struct Series<'a> {
    pub name: &'a str,
    pub points: Vec<(f64, f64)>,
    pub colour: RGBColor,
}

/// A line chart written atomically as PNG.
pub fn line_chart(
    path: &Path,
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<()> {
    let (x0, mut x1, y0, y1) = extent(series.iter().flat_map(|s| s.points.iter().copied()));
    if x1 <= x0 {
        x1 = x0 + 1.0;
    }
    let pad = ((y1 - y0) * 0.05).max(1e-9);
    png(path, (900, 500), |root| {
        root.fill(&WHITE)?;
        let mut chart = builder(root, title, 22, 12, (40, 60))
            .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
        axes(&mut chart, x_label, y_label, 14)?;
        for s in series {
            let c = s.colour;
            chart
                .draw_series(LineSeries::new(s.points.iter().copied(), c.stroke_width(2)))?
                .label(s.name)
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2))
                });
        }
        legend(&mut chart, 0.8, 14)?;
        Ok(())
    })
}

/// A heat map of `values[row][col]` (row 0 at the bottom) written atomically as PNG.
pub fn heat_map(path: &Path, title: &str, values: &[Vec<f64>]) -> Result<()> {
    let ny = values.len().max(1);
    let nx = values.first().map_or(1, |r| r.len()).max(1);
    let max = values
        .iter()
        .flatten()
        .copied()
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-12);
    png(path, (640, 560), |root| {
        root.fill(&WHITE)?;
        let caption = format!("{title} (max {max:.3})");
        let mut chart = builder(root, &caption, 18, 12, (30, 40))
            .build_cartesian_2d(0.0..nx as f64, 0.0..ny as f64)?;
        bare_axes(&mut chart, "coarse cell x", "coarse cell y")?;
        chart.draw_series(values.iter().enumerate().flat_map(|(iy, row)| {
            row.iter().enumerate().map(move |(ix, &v)| {
                let t = if v.is_finite() {
                    (v / max).clamp(0.0, 1.0)
                } else {
                    0.0
                };
                // White → orange → dark red.
                let c = RGBColor(
                    (255.0 - 60.0 * t) as u8,
                    (255.0 - 215.0 * t) as u8,
                    (255.0 - 235.0 * t) as u8,
                );
                Rectangle::new(
                    [(ix as f64, iy as f64), (ix as f64 + 1.0, iy as f64 + 1.0)],
                    c.filled(),
                )
            })
        }))?;
        Ok(())
    })
}

/// A top view of a scene: obstacle cells (grey), optional per-cell vectors (a navigation field,
/// drawn as short strokes with a dot at the head), polylines (arrows, paths) and agents coloured
/// by group.
#[allow(clippy::too_many_arguments)]
pub fn scene_plot(
    path: &Path,
    title: &str,
    grid: &crate::data::Grid,
    obstacles: &ndarray::Array2<u8>,
    vectors: Option<&[[f64; 2]]>,
    lines: &[Vec<[f64; 2]>],
    agents: &[([f64; 2], usize)],
) -> Result<()> {
    let size = grid.size();
    let wpx = 1000u32;
    let hpx = ((wpx as f64 - 80.0) * size[1] / size[0] + 90.0).clamp(200.0, 1400.0) as u32;
    png(path, (wpx, hpx), |root| {
        root.fill(&WHITE)?;
        let mut chart = builder(root, title, 20, 10, (30, 40)).build_cartesian_2d(
            grid.origin[0]..grid.origin[0] + size[0],
            grid.origin[1]..grid.origin[1] + size[1],
        )?;
        bare_axes(&mut chart, "x (BL)", "y (BL)")?;
        let c = grid.cell_size;
        chart.draw_series(obstacles.indexed_iter().filter(|(_, &v)| v != 0).map(
            |((iy, ix), _)| {
                let p = grid.centre(ix, iy);
                Rectangle::new(
                    [
                        (p[0] - c / 2.0, p[1] - c / 2.0),
                        (p[0] + c / 2.0, p[1] + c / 2.0),
                    ],
                    RGBColor(110, 110, 110).filled(),
                )
            },
        ))?;
        if let Some(v) = vectors {
            let mut strokes = Vec::new();
            for iy in 0..grid.ny {
                for ix in 0..grid.nx {
                    let d = v[iy * grid.nx + ix];
                    let l = d[0].hypot(d[1]);
                    if l > 1e-6 {
                        let p = grid.centre(ix, iy);
                        let k = 0.45 * c * l.min(1.0) / l;
                        strokes.push((p, [p[0] + d[0] * k, p[1] + d[1] * k]));
                    }
                }
            }
            chart.draw_series(strokes.iter().map(|(a, b)| {
                PathElement::new(vec![(a[0], a[1]), (b[0], b[1])], RGBColor(31, 119, 180))
            }))?;
            chart.draw_series(
                strokes
                    .iter()
                    .map(|(_, b)| Circle::new((b[0], b[1]), 1, RGBColor(31, 119, 180).filled())),
            )?;
        }
        for l in lines {
            chart.draw_series(LineSeries::new(
                l.iter().map(|p| (p[0], p[1])),
                RGBColor(214, 39, 40).stroke_width(2),
            ))?;
        }
        let palette = [
            RGBColor(0, 0, 0),
            RGBColor(255, 127, 14),
            RGBColor(44, 160, 44),
            RGBColor(148, 103, 189),
        ];
        chart.draw_series(
            agents
                .iter()
                .map(|(p, g)| Circle::new((p[0], p[1]), 2, palette[g % 4].filled())),
        )?;
        Ok(())
    })
}

/// A group of polylines of one colour, with a legend entry, for [`paths_plot`].
pub struct PathGroup<'a> {
    pub name: &'a str,
    pub lines: Vec<Vec<(f64, f64)>>,
    pub colour: RGBColor,
    pub width: u32,
}

/// Polylines (trajectories) and marked points on axes of equal scale, written atomically as PNG
/// of `size` pixels.
pub fn paths_plot(
    path: &Path,
    title: &str,
    labels: (&str, &str),
    groups: &[PathGroup],
    marks: &[(&str, (f64, f64), RGBColor)],
    size: (u32, u32),
) -> Result<()> {
    let (x0, x1, y0, y1) = extent(
        groups
            .iter()
            .flat_map(|g| g.lines.iter().flatten().copied())
            .chain(marks.iter().map(|m| m.1)),
    );
    // Equal scale: widen the narrower range to the plot area's aspect ratio.
    let (aw, ah) = (size.0 as f64 - 90.0, size.1 as f64 - 80.0);
    let (w, h) = ((x1 - x0).max(1e-9) * 1.06, (y1 - y0).max(1e-9) * 1.06);
    let per_px = (w / aw).max(h / ah);
    let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
    let (hx, hy) = (0.5 * per_px * aw, 0.5 * per_px * ah);
    png(path, size, |root| {
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(10)
            .x_label_area_size(35)
            .y_label_area_size(50)
            .build_cartesian_2d((cx - hx)..(cx + hx), (cy - hy)..(cy + hy))?;
        axes(&mut chart, labels.0, labels.1, 13)?;
        for g in groups {
            let style = g.colour.stroke_width(g.width);
            let mut first = true;
            for l in &g.lines {
                let s = chart.draw_series(LineSeries::new(l.iter().copied(), style))?;
                if first {
                    let c = g.colour;
                    s.label(g.name).legend(move |(x, y)| {
                        PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(3))
                    });
                    first = false;
                }
            }
        }
        for (name, p, c) in marks {
            let c = *c;
            chart
                .draw_series(std::iter::once(Cross::new(*p, 7, c.stroke_width(3))))?
                .label(*name)
                .legend(move |(x, y)| Cross::new((x + 10, y), 5, c.stroke_width(2)));
        }
        legend(&mut chart, 0.85, 13)?;
        Ok(())
    })
}

/// Filled, outlined polygons in pixel coordinates (drawn in the order given: painter's
/// algorithm) over a vertical gradient from `sky.0` (top) to `sky.1`, written atomically as PNG.
pub fn polygons_png(
    path: &Path,
    size: (u32, u32),
    sky: (RGBColor, RGBColor),
    polygons: &[(Vec<(i32, i32)>, RGBColor)],
    caption: &str,
) -> Result<()> {
    png(path, size, |root| {
        let mix = |a: u8, b: u8, t: f64| (a as f64 + (b as f64 - a as f64) * t).round() as u8;
        for y in 0..size.1 as i32 {
            let t = y as f64 / size.1.max(1) as f64;
            let c = RGBColor(
                mix(sky.0 .0, sky.1 .0, t),
                mix(sky.0 .1, sky.1 .1, t),
                mix(sky.0 .2, sky.1 .2, t),
            );
            root.draw(&PathElement::new(vec![(0, y), (size.0 as i32, y)], c))?;
        }
        for (pts, c) in polygons {
            root.draw(&Polygon::new(pts.clone(), c.filled()))?;
        }
        root.draw(&Text::new(
            caption.to_string(),
            (10, 10),
            ("sans-serif", 18).into_font(),
        ))?;
        Ok(())
    })
}
