//! Stage 6: pictures of a 3D flock — top and side views as PNG, the same two views animated as an
//! MJPG AVI (feature `video`), and one frame of an exported glTF flock rendered through a camera.
//!
//! Top view: world x (right) and y (up the page). Side view: the horizontal distance from the
//! camera along its line of sight, and the height z — depth errors show as horizontal offsets.

use crate::data::camera::Camera;
use crate::data::gltf::{bird_mesh, read_glb, rotate};
use crate::data::tracks::Tracks;
use crate::error::{Error, Result};
use crate::plot::{paths_plot, polygons_png, PathGroup};
use plotters::style::RGBColor;
use std::path::Path;

/// One flock to draw (3D tracks) in one colour.
pub struct Layer<'a> {
    pub name: &'a str,
    pub tracks: &'a Tracks,
    pub colour: RGBColor,
}

/// The palette of layers: truth grey, then blue, orange, green, red.
pub const COLOURS: [RGBColor; 5] = [
    RGBColor(150, 150, 150),
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
];

type V3 = [f64; 3];

/// The horizontal unit vector of the camera's line of sight.
fn sight(camera: &Camera) -> [f64; 2] {
    let z = camera.rotation[2];
    let n = z[0].hypot(z[1]).max(1e-12);
    [z[0] / n, z[1] / n]
}

/// Side-view coordinates of a world point: (distance along the line of sight, height).
fn side(camera: &Camera, p: V3) -> (f64, f64) {
    let s = sight(camera);
    let c = camera.position;
    ((p[0] - c[0]) * s[0] + (p[1] - c[1]) * s[1], p[2])
}

/// Polylines per bird (a gap in frames breaks the line).
fn lines(t: &Tracks, f: impl Fn(V3) -> (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let mut out = Vec::new();
    for rows in t.by_id().values() {
        let mut line: Vec<(f64, f64)> = Vec::new();
        for (k, &i) in rows.iter().enumerate() {
            if k > 0 && t.rows[i].frame != t.rows[rows[k - 1]].frame + 1 {
                out.push(std::mem::take(&mut line));
            }
            line.push(f(t.rows[i].pos));
        }
        out.push(line);
    }
    out
}

/// Writes the top view to `top` and the side view to `side_png`.
pub fn views_png(
    top: &Path,
    side_png: &Path,
    title: &str,
    layers: &[Layer],
    camera: &Camera,
) -> Result<()> {
    let u = camera.units.as_str();
    for l in layers {
        if l.tracks.meta.dimension != 3 {
            return Err(Error::invalid(format!("layer '{}' is not 3D", l.name)));
        }
    }
    let group = |f: &dyn Fn(V3) -> (f64, f64)| -> Vec<PathGroup> {
        layers
            .iter()
            .map(|l| PathGroup {
                name: l.name,
                lines: lines(l.tracks, f),
                colour: l.colour,
                width: 1,
            })
            .collect()
    };
    let c = camera.position;
    paths_plot(
        top,
        &format!("{title}: top view"),
        (&format!("x ({u})"), &format!("y ({u})")),
        &group(&|p| (p[0], p[1])),
        &[("camera", (c[0], c[1]), RGBColor(0, 0, 0))],
        (1000, 800),
    )?;
    paths_plot(
        side_png,
        &format!("{title}: side view"),
        (
            &format!("distance along the line of sight ({u})"),
            &format!("height z ({u})"),
        ),
        &group(&|p| side(camera, p)),
        &[("camera", (0.0, c[2]), RGBColor(0, 0, 0))],
        (1200, 600),
    )
}

/// The triangles (positions, normals; three vertices per face) of the GLB's first mesh, or a
/// unit-length bird when it has none.
fn mesh_of(g: &crate::data::gltf::Glb) -> Result<(Vec<V3>, Vec<V3>)> {
    use gltf_json::mesh::Semantic;
    use gltf_json::validation::Checked::Valid;
    let Some(prim) = g.root.meshes.first().and_then(|m| m.primitives.first()) else {
        return Ok(bird_mesh(1.0));
    };
    let read = |s: Semantic| -> Result<Vec<V3>> {
        let a = prim
            .attributes
            .get(&Valid(s))
            .ok_or_else(|| Error::invalid("the mesh lacks positions or normals"))?;
        Ok(g.floats(*a)?
            .chunks_exact(3)
            .map(|c| [c[0].into(), c[1].into(), c[2].into()])
            .collect())
    };
    Ok((read(Semantic::Positions)?, read(Semantic::Normals)?))
}

/// Renders time `t` (s) of the GLB at `glb` as seen by `camera` (herdfit world coordinates, z up;
/// the glTF's y-up coordinates are turned back, (x, y, z) → (x, −z, y)) into a PNG: every node's
/// bird mesh, flat-shaded, drawn far to near. Returns the number of birds drawn.
pub fn render_glb(glb: &Path, t: f64, camera: &Camera, out: &Path) -> Result<usize> {
    camera.check()?;
    let g = read_glb(glb)?;
    let nodes = g.sample(t).map_err(|e| e.in_file(glb))?;
    let (pos, nor) = mesh_of(&g).map_err(|e| e.in_file(glb))?;
    let light = {
        let l: V3 = [0.3, -0.4, 0.87];
        let n = (l[0] * l[0] + l[1] * l[1] + l[2] * l[2]).sqrt();
        l.map(|c| c / n)
    };
    let to_world = |p: V3| [p[0], -p[2], p[1]];
    type Poly = (f64, Vec<(i32, i32)>, RGBColor);
    let mut polys: Vec<Poly> = Vec::new();
    let mut drawn = 0;
    for (_, tr, q, s) in &nodes {
        if s.iter().all(|x| *x == 0.0) {
            continue;
        }
        drawn += 1;
        for (k, tri) in pos.chunks(3).enumerate() {
            let world: Vec<V3> = tri
                .iter()
                .map(|v| {
                    let r = rotate(*q, [v[0] * s[0], v[1] * s[1], v[2] * s[2]]);
                    to_world([r[0] + tr[0], r[1] + tr[1], r[2] + tr[2]])
                })
                .collect();
            let proj: Option<Vec<([f64; 2], f64)>> =
                world.iter().map(|w| camera.project(*w)).collect();
            let Some(proj) = proj else { continue };
            let n = to_world(rotate(*q, nor[3 * k]));
            let shade = 0.35 + 0.65 * (n[0] * light[0] + n[1] * light[1] + n[2] * light[2]).abs();
            let v = (20.0 + 45.0 * shade) as u8;
            let depth = proj.iter().map(|p| p.1).sum::<f64>() / 3.0;
            polys.push((
                depth,
                proj.iter()
                    .map(|p| (p.0[0].round() as i32, p.0[1].round() as i32))
                    .collect(),
                RGBColor(v, v, (v as f64 * 1.1) as u8),
            ));
        }
    }
    polys.sort_by(|a, b| b.0.total_cmp(&a.0));
    let list: Vec<(Vec<(i32, i32)>, RGBColor)> = polys.into_iter().map(|p| (p.1, p.2)).collect();
    polygons_png(
        out,
        (camera.width, camera.height),
        (RGBColor(120, 165, 215), RGBColor(215, 230, 240)),
        &list,
        &format!(
            "{} at t = {t:.2} s ({drawn} birds)",
            glb.file_name()
                .map_or(String::new(), |f| f.to_string_lossy().into_owned())
        ),
    )?;
    Ok(drawn)
}

#[cfg(feature = "video")]
pub use video::views_avi;

#[cfg(feature = "video")]
mod video {
    use super::{side, Layer, V3};
    use crate::data::camera::Camera;
    use crate::error::{Error, Result};
    use opencv::core::{Mat, Point, Scalar, CV_8UC3};
    use opencv::imgproc;
    use std::path::Path;

    fn cv(path: &Path) -> impl Fn(opencv::Error) -> Error + '_ {
        move |e| Error::file(path, format!("OpenCV: {e}"))
    }

    /// A world → pixel map of one panel (equal scale, 5% margin).
    struct Panel {
        x0: f64,
        y0: f64,
        scale: f64,
        left: i32,
        h: i32,
    }

    impl Panel {
        fn new(pts: &[(f64, f64)], left: i32, w: i32, h: i32) -> Panel {
            let (mut a, mut b, mut c, mut d) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
            for p in pts {
                a = a.min(p.0);
                b = b.max(p.0);
                c = c.min(p.1);
                d = d.max(p.1);
            }
            let scale = 0.9 * (w as f64 / (b - a).max(1e-9)).min(h as f64 / (d - c).max(1e-9));
            Panel {
                x0: 0.5 * (a + b) - 0.5 * w as f64 / scale,
                y0: 0.5 * (c + d) - 0.5 * h as f64 / scale,
                scale,
                left,
                h,
            }
        }
        fn px(&self, p: (f64, f64)) -> Point {
            Point::new(
                self.left + ((p.0 - self.x0) * self.scale).round() as i32,
                self.h - ((p.1 - self.y0) * self.scale).round() as i32,
            )
        }
    }

    /// The top (left) and side (right) views animated, one video frame per tracks frame, with a
    /// one-second trail; MJPG AVI written through a temporary sibling.
    pub fn views_avi(path: &Path, layers: &[Layer], camera: &Camera, fps: f64) -> Result<()> {
        let (w, h) = (640, 540);
        let mut all_top = Vec::new();
        let mut all_side = Vec::new();
        for l in layers {
            for r in &l.tracks.rows {
                all_top.push((r.pos[0], r.pos[1]));
                all_side.push(side(camera, r.pos));
            }
        }
        all_top.push((camera.position[0], camera.position[1]));
        let top = Panel::new(&all_top, 0, w, h);
        let sidep = Panel::new(&all_side, w, w, h);
        let frames: Vec<u64> = {
            let mut f: Vec<u64> = layers
                .iter()
                .flat_map(|l| l.tracks.rows.iter().map(|r| r.frame))
                .collect();
            f.sort_unstable();
            f.dedup();
            f
        };
        let mut writer = crate::video::AviWriter::create(path, fps, 2 * w, h)?;
        let trail = fps.round().max(1.0) as u64;
        let per_layer: Vec<Vec<Vec<(u64, V3)>>> = layers
            .iter()
            .map(|l| {
                l.tracks
                    .by_id()
                    .values()
                    .map(|rows| {
                        rows.iter()
                            .map(|&i| (l.tracks.rows[i].frame, l.tracks.rows[i].pos))
                            .collect()
                    })
                    .collect()
            })
            .collect();
        for &f in &frames {
            let mut m = Mat::new_rows_cols_with_default(h, 2 * w, CV_8UC3, Scalar::all(255.0))
                .map_err(cv(path))?;
            imgproc::line(
                &mut m,
                Point::new(w, 0),
                Point::new(w, h),
                Scalar::all(0.0),
                1,
                imgproc::LINE_8,
                0,
            )
            .map_err(cv(path))?;
            for (l, birds) in layers.iter().zip(&per_layer) {
                let c = l.colour;
                let col = Scalar::new(c.2 as f64, c.1 as f64, c.0 as f64, 0.0);
                for bird in birds {
                    let seen: Vec<&(u64, V3)> = bird
                        .iter()
                        .filter(|(g, _)| *g <= f && *g + trail >= f)
                        .collect();
                    for (panel, proj) in [
                        (&top, &(|p: V3| (p[0], p[1])) as &dyn Fn(V3) -> (f64, f64)),
                        (&sidep, &|p: V3| side(camera, p)),
                    ] {
                        for s in seen.windows(2) {
                            imgproc::line(
                                &mut m,
                                panel.px(proj(s[0].1)),
                                panel.px(proj(s[1].1)),
                                col,
                                1,
                                imgproc::LINE_AA,
                                0,
                            )
                            .map_err(cv(path))?;
                        }
                        if let Some(last) = seen.last().filter(|(g, _)| *g == f) {
                            imgproc::circle(
                                &mut m,
                                panel.px(proj(last.1)),
                                3,
                                col,
                                -1,
                                imgproc::LINE_AA,
                                0,
                            )
                            .map_err(cv(path))?;
                        }
                    }
                }
            }
            for (panel, p, label) in [
                (
                    &top,
                    (camera.position[0], camera.position[1]),
                    "top view (x, y)",
                ),
                (
                    &sidep,
                    (0.0, camera.position[2]),
                    "side view (line of sight, z)",
                ),
            ] {
                imgproc::draw_marker(
                    &mut m,
                    panel.px(p),
                    Scalar::all(0.0),
                    imgproc::MARKER_CROSS,
                    14,
                    2,
                    imgproc::LINE_8,
                )
                .map_err(cv(path))?;
                imgproc::put_text(
                    &mut m,
                    label,
                    Point::new(panel.left + 10, 22),
                    imgproc::FONT_HERSHEY_SIMPLEX,
                    0.6,
                    Scalar::all(0.0),
                    1,
                    imgproc::LINE_AA,
                    false,
                )
                .map_err(cv(path))?;
            }
            writer.write(&m)?;
        }
        writer.commit()
    }
}
