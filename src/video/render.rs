//! Overhead rendering of a herd: agents as body-length ellipses of one colour over a textured
//! ground, obstacle cells in dark grey, optionally seen through a moving camera (smooth pan, zoom
//! and rotation starting from the identity at frame 0). Used by `synth --video` to make test
//! videos with known truth for extraction.

use crate::data::agents::AgentRow;
use crate::data::Grid;
use crate::error::{Error, Result};
use crate::video::avi::{AviWriter, PendingVideo};
use ndarray::Array2;
use opencv::core::{Mat, Point, Scalar, Size, CV_8UC3};
use opencv::imgproc;
use opencv::prelude::*;
use serde::Serialize;
use std::path::Path;

/// Rendering settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RenderConfig {
    /// Pixels per body length.
    pub px_per_bl: f64,
    /// Body colour, RGB.
    pub body_rgb: [u8; 3],
    /// Apply the smooth camera motion of [`camera_at`].
    pub camera_motion: bool,
    /// Seed of the ground texture.
    pub seed: u64,
}

impl RenderConfig {
    /// Checks the scale (at least 2 pixels per body length); errors name the key.
    pub fn check(&self) -> Result<()> {
        crate::limits::check_px_per_bl(self.px_per_bl)
    }
}

/// Body ellipse: full length 1 BL, full width [`BODY_WIDTH_BL`].
pub use crate::data::clip::BODY_WIDTH_BL;

/// The camera of frame `f` of `frames`: image-space similarity about the image centre,
/// `p' = c + t + z R(θ) (p − c)`. Identity at frame 0, easing smoothly (raised cosine) to a pan of
/// (6%, −4%) of the frame, a zoom of 1.15 and a rotation of 8° at the last frame.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Camera {
    pub frame: usize,
    pub pan_px: [f64; 2],
    pub zoom: f64,
    pub rotation_deg: f64,
}

/// Camera pose of frame `f` (of `frames`) for a `w × h` image.
pub fn camera_at(f: usize, frames: usize, w: usize, h: usize) -> Camera {
    let s = if frames > 1 {
        0.5 * (1.0 - (std::f64::consts::PI * f as f64 / (frames - 1) as f64).cos())
    } else {
        0.0
    };
    Camera {
        frame: f,
        pan_px: [0.06 * w as f64 * s, -0.04 * h as f64 * s],
        zoom: 1.0 + 0.15 * s,
        rotation_deg: 8.0 * s,
    }
}

impl Camera {
    /// The 2×3 affine matrix mapping world-render pixels to camera pixels.
    pub fn matrix(&self, w: usize, h: usize) -> [[f64; 3]; 2] {
        let (c, s) = {
            let a = self.rotation_deg.to_radians();
            (a.cos() * self.zoom, a.sin() * self.zoom)
        };
        let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
        [
            [c, -s, cx + self.pan_px[0] - c * cx + s * cy],
            [s, c, cy + self.pan_px[1] - s * cx - c * cy],
        ]
    }
}

fn cv(path: &Path) -> impl Fn(opencv::Error) -> Error + '_ {
    move |e| Error::file(path, format!("OpenCV: {}", e.message))
}

/// Image size (width, height) for a grid: the grid at `px_per_bl`, rounded up to even numbers.
pub fn frame_size(grid: &Grid, px_per_bl: f64) -> (usize, usize) {
    let s = grid.size();
    let even = |v: f64| ((v * px_per_bl).ceil() as usize).div_ceil(2) * 2;
    (even(s[0]).max(2), even(s[1]).max(2))
}

/// World position → world-render pixel (y up in the world, down in the image).
pub fn world_to_px(grid: &Grid, px_per_bl: f64, h: usize, p: [f64; 2]) -> [f64; 2] {
    [
        (p[0] - grid.origin[0]) * px_per_bl,
        h as f64 - (p[1] - grid.origin[1]) * px_per_bl,
    ]
}

/// A smooth, deterministic grass-like texture (BGR), from a few octaves of value noise.
fn ground(w: usize, h: usize, seed: u64) -> Vec<u8> {
    let hash = |x: i64, y: i64, o: u64| -> f64 {
        let mut z = (x as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add((y as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
            .wrapping_add(seed.wrapping_add(o).wrapping_mul(0x1656_67B1_9E37_79F9));
        z ^= z >> 29;
        z = z.wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z ^= z >> 32;
        (z >> 11) as f64 / (1u64 << 53) as f64
    };
    let noise = |x: f64, y: f64, cell: f64, o: u64| -> f64 {
        let (fx, fy) = (x / cell, y / cell);
        let (ix, iy) = (fx.floor() as i64, fy.floor() as i64);
        let (tx, ty) = (fx - ix as f64, fy - iy as f64);
        let (sx, sy) = (tx * tx * (3.0 - 2.0 * tx), ty * ty * (3.0 - 2.0 * ty));
        let a = hash(ix, iy, o) * (1.0 - sx) + hash(ix + 1, iy, o) * sx;
        let b = hash(ix, iy + 1, o) * (1.0 - sx) + hash(ix + 1, iy + 1, o) * sx;
        a * (1.0 - sy) + b * sy
    };
    let mut buf = vec![0u8; w * h * 3];
    for y in 0..h {
        for x in 0..w {
            let (fx, fy) = (x as f64, y as f64);
            let n = 0.45 * noise(fx, fy, 24.0, 1)
                + 0.35 * noise(fx, fy, 6.0, 2)
                + 0.2 * noise(fx, fy, 2.0, 3);
            // Earth patches and small stones give trackable structure at several scales.
            let earth = (noise(fx, fy, 40.0, 4) - 0.55).max(0.0) * 2.5;
            let stone = if noise(fx, fy, 3.0, 5) > 0.82 {
                0.6
            } else {
                0.0
            };
            let i = (y * w + x) * 3;
            // Olive-green grass with brown earth (B, G, R); stones are grey.
            let (b, g, r) = (
                30.0 + 40.0 * n + 10.0 * earth,
                80.0 + 80.0 * n - 30.0 * earth,
                55.0 + 60.0 * n + 25.0 * earth,
            );
            let mix =
                |v: f64, grey: f64| (v * (1.0 - stone) + grey * stone).clamp(0.0, 200.0) as u8;
            buf[i] = mix(b, 130.0);
            buf[i + 1] = mix(g, 130.0);
            buf[i + 2] = mix(r, 125.0);
        }
    }
    buf
}

fn mat_from_bgr(buf: &[u8], w: usize, h: usize, path: &Path) -> Result<Mat> {
    let mut m = Mat::new_rows_cols_with_default(h as i32, w as i32, CV_8UC3, Scalar::all(0.0))
        .map_err(cv(path))?;
    m.data_bytes_mut().map_err(cv(path))?.copy_from_slice(buf);
    Ok(m)
}

/// The static layer of a rendered frame: the ground texture and the obstacle cells.
fn base_layer(
    w: usize,
    h: usize,
    grid: &Grid,
    obstacles: &Array2<u8>,
    cfg: &RenderConfig,
    path: &Path,
) -> Result<Mat> {
    let mut base = mat_from_bgr(&ground(w, h, cfg.seed), w, h, path)?;
    let s = cfg.px_per_bl;
    for ((iy, ix), &v) in obstacles.indexed_iter() {
        if v == 0 {
            continue;
        }
        let c = grid.centre(ix, iy);
        let half = grid.cell_size / 2.0;
        let a = world_to_px(grid, s, h, [c[0] - half, c[1] + half]);
        let b = world_to_px(grid, s, h, [c[0] + half, c[1] - half]);
        let rect = opencv::core::Rect::new(
            a[0].round() as i32,
            a[1].round() as i32,
            (b[0] - a[0]).round() as i32,
            (b[1] - a[1]).round() as i32,
        );
        imgproc::rectangle(
            &mut base,
            rect,
            Scalar::new(55.0, 60.0, 62.0, 0.0),
            -1,
            imgproc::LINE_8,
            0,
        )
        .map_err(cv(path))?;
    }
    Ok(base)
}

/// Draws every agent as an anti-aliased ellipse of one body length by [`BODY_WIDTH_BL`], along
/// its velocity.
fn draw_agents(
    frame: &mut Mat,
    agents: &[AgentRow],
    grid: &Grid,
    cfg: &RenderConfig,
    path: &Path,
) -> Result<()> {
    let s = cfg.px_per_bl;
    let h = frame.rows() as usize;
    let colour = Scalar::new(
        cfg.body_rgb[2] as f64,
        cfg.body_rgb[1] as f64,
        cfg.body_rgb[0] as f64,
        0.0,
    );
    const SHIFT: i32 = 4;
    let sub = (1 << SHIFT) as f64;
    // OpenCV strokes the outline of a filled anti-aliased ellipse with a one-pixel line centred
    // on it, which makes the body a pixel longer and wider than its axes (measured: 11 × 6 px
    // at half intensity for axes of 10 × 4 px); half a pixel off each half-axis draws the body
    // at its size.
    let half = |len: f64| ((0.5 * len - 0.5).max(0.0) * sub).round() as i32;
    let axes = Size::new(half(s), half(BODY_WIDTH_BL * s));
    for a in agents {
        let p = world_to_px(grid, s, h, [a.x, a.y]);
        let angle = -a.vy.atan2(a.vx).to_degrees();
        imgproc::ellipse(
            frame,
            Point::new((p[0] * sub).round() as i32, (p[1] * sub).round() as i32),
            axes,
            angle,
            0.0,
            360.0,
            colour,
            -1,
            imgproc::LINE_AA,
            SHIFT,
        )
        .map_err(cv(path))?;
    }
    Ok(())
}

/// Renders one frame of `agents` as the video would show it (a still's image) into `path` (PNG),
/// and the bare ground (its background) into `ground`; both written atomically.
pub fn render_image(
    path: &Path,
    ground: &Path,
    agents: &[AgentRow],
    grid: &Grid,
    obstacles: &Array2<u8>,
    cfg: &RenderConfig,
) -> Result<()> {
    cfg.check()?;
    let (w, h) = frame_size(grid, cfg.px_per_bl);
    if w * h > 8192 * 8192 {
        return Err(Error::invalid(format!("a {w}×{h} image is too large")));
    }
    let base = base_layer(w, h, grid, obstacles, cfg, path)?;
    let mut frame = base.clone();
    draw_agents(&mut frame, agents, grid, cfg, path)?;
    for (p, m) in [(ground, &base), (path, &frame)] {
        let mut buf = opencv::core::Vector::<u8>::new();
        opencv::imgcodecs::imencode(".png", m, &mut buf, &opencv::core::Vector::new())
            .map_err(cv(p))?;
        crate::data::atomic::write_atomic(p, buf.as_slice())?;
    }
    Ok(())
}

/// Renders `frames` (positions and velocities per frame) as an MJPG AVI for `path`, into a
/// temporary sibling that [`PendingVideo::commit`] renames into place. Returns the camera pose of
/// every frame.
pub fn render_video(
    path: &Path,
    frames: &[Vec<AgentRow>],
    grid: &Grid,
    obstacles: &Array2<u8>,
    fps: f64,
    cfg: &RenderConfig,
    mut progress: impl FnMut(),
) -> Result<(Vec<Camera>, PendingVideo)> {
    cfg.check()?;
    let (w, h) = frame_size(grid, cfg.px_per_bl);
    if w * h > 8192 * 8192 {
        return Err(Error::invalid(format!(
            "a {w}×{h} video frame is too large"
        )));
    }
    let mut writer = AviWriter::create(path, fps, w as i32, h as i32)?;
    let base = base_layer(w, h, grid, obstacles, cfg, path)?;
    let mut cameras = Vec::with_capacity(frames.len());
    let mut frame = Mat::default();
    let mut out = Mat::default();
    for (f, agents) in frames.iter().enumerate() {
        base.copy_to(&mut frame).map_err(cv(path))?;
        draw_agents(&mut frame, agents, grid, cfg, path)?;
        let cam = if cfg.camera_motion {
            camera_at(f, frames.len(), w, h)
        } else {
            camera_at(0, 1, w, h)
        };
        if cfg.camera_motion && f > 0 {
            let m = cam.matrix(w, h);
            let mm = Mat::from_slice_2d(&[m[0].to_vec(), m[1].to_vec()]).map_err(cv(path))?;
            imgproc::warp_affine(
                &frame,
                &mut out,
                &mm,
                Size::new(w as i32, h as i32),
                imgproc::INTER_LINEAR,
                opencv::core::BORDER_REFLECT,
                Scalar::all(0.0),
            )
            .map_err(cv(path))?;
            writer.write(&out)?;
        } else {
            writer.write(&frame)?;
        }
        cameras.push(cam);
        progress();
    }
    Ok((cameras, writer.finish()?))
}

/// Side-by-side comparison video: the clip's fields (left: density as cell shading, mean velocity
/// arrows) and the simulation (right: the same from its rasterised fields, agents as dots), for
/// frames `start..start + sim_frames.len()` of the clip. MJPG AVI, written atomically.
pub fn render_comparison(
    path: &Path,
    clip: &crate::data::ClipFields,
    sim: &crate::data::ClipFields,
    sim_frames: &[Vec<AgentRow>],
    start: usize,
) -> Result<()> {
    let g = clip.grid();
    let size = g.size();
    let s = (400.0 / size[0].max(size[1])).max(2.0);
    let (w, h) = frame_size(&g, s);
    let mut writer = AviWriter::create(path, clip.meta.fps, 2 * w as i32 + 8, h as i32)?;
    let max = (0..clip.frames())
        .map(|f| {
            clip.density
                .index_axis(ndarray::Axis(0), f)
                .iter()
                .cloned()
                .fold(0.0f32, f32::max)
        })
        .fold(0.0f32, f32::max)
        .max(1e-6) as f64;
    for (k, agents) in sim_frames.iter().enumerate() {
        let f = start + k;
        let mut img = Mat::new_rows_cols_with_default(
            h as i32,
            2 * w as i32 + 8,
            CV_8UC3,
            Scalar::all(255.0),
        )
        .map_err(cv(path))?;
        for (panel, src, fr) in [(0usize, clip, f), (1usize, sim, k)] {
            let ox = panel as f64 * (w as f64 + 8.0);
            for iy in 0..g.ny {
                for ix in 0..g.nx {
                    let d = src.density[[fr, iy, ix]] as f64;
                    let c = g.centre(ix, iy);
                    let half = g.cell_size / 2.0;
                    let a = world_to_px(&g, s, h, [c[0] - half, c[1] + half]);
                    let b = world_to_px(&g, s, h, [c[0] + half, c[1] - half]);
                    let rect = opencv::core::Rect::new(
                        (ox + a[0]) as i32,
                        a[1] as i32,
                        (b[0] - a[0]).ceil() as i32,
                        (b[1] - a[1]).ceil() as i32,
                    );
                    let t = (d / max).clamp(0.0, 1.0);
                    let colour = if clip.obstacles[[iy, ix]] != 0 {
                        Scalar::new(80.0, 80.0, 80.0, 0.0)
                    } else {
                        Scalar::new(255.0 * (1.0 - t), 255.0 - 120.0 * t, 255.0 - 40.0 * t, 0.0)
                    };
                    imgproc::rectangle(&mut img, rect, colour, -1, imgproc::LINE_8, 0)
                        .map_err(cv(path))?;
                    let v = [
                        src.velocity[[fr, iy, ix, 0]] as f64,
                        src.velocity[[fr, iy, ix, 1]] as f64,
                    ];
                    let l = v[0].hypot(v[1]);
                    if d > 0.0 && l > 1e-9 {
                        let p = world_to_px(&g, s, h, c);
                        let k = 0.45 * g.cell_size * s / l;
                        imgproc::arrowed_line(
                            &mut img,
                            Point::new((ox + p[0]) as i32, p[1] as i32),
                            Point::new((ox + p[0] + v[0] * k) as i32, (p[1] - v[1] * k) as i32),
                            Scalar::new(60.0, 30.0, 0.0, 0.0),
                            1,
                            imgproc::LINE_AA,
                            0,
                            0.3,
                        )
                        .map_err(cv(path))?;
                    }
                }
            }
        }
        for a in agents {
            let p = world_to_px(&g, s, h, [a.x, a.y]);
            imgproc::circle(
                &mut img,
                Point::new((w as f64 + 8.0 + p[0]) as i32, p[1] as i32),
                1,
                Scalar::new(0.0, 0.0, 200.0, 0.0),
                -1,
                imgproc::LINE_8,
                0,
            )
            .map_err(cv(path))?;
        }
        writer.write(&img)?;
    }
    writer.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_is_identity_at_frame_zero_and_smooth() {
        let c0 = camera_at(0, 50, 200, 100);
        let m = c0.matrix(200, 100);
        assert_eq!(m, [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        let last = camera_at(49, 50, 200, 100);
        assert!((last.zoom - 1.15).abs() < 1e-12 && (last.rotation_deg - 8.0).abs() < 1e-12);
        // The image centre moves by the pan only.
        let m = last.matrix(200, 100);
        let cx = m[0][0] * 100.0 + m[0][1] * 50.0 + m[0][2];
        let cy = m[1][0] * 100.0 + m[1][1] * 50.0 + m[1][2];
        assert!(
            (cx - 112.0).abs() < 1e-9 && (cy - 46.0).abs() < 1e-9,
            "{cx} {cy}"
        );
        // Small steps between frames.
        for f in 1..50 {
            let (a, b) = (camera_at(f - 1, 50, 200, 100), camera_at(f, 50, 200, 100));
            assert!((b.rotation_deg - a.rotation_deg).abs() < 0.3);
        }
    }

    #[test]
    fn frame_size_is_even() {
        let g = Grid {
            origin: [0.0, 0.0],
            cell_size: 2.5,
            nx: 7,
            ny: 3,
        };
        assert_eq!(frame_size(&g, 5.0), (88, 38));
    }
}
