//! `herdfit.camera/1`: one static pinhole camera (intrinsics and pose), shared by every system that
//! relates image pixels to world positions.
//!
//! ```json
//! {"schema": "herdfit.camera/1", "units": "m", "width": 1920, "height": 1080,
//!  "fx": 1400, "fy": 1400, "cx": 960, "cy": 540,
//!  "rotation": [[1,0,0],[0,0,-1],[0,1,0]], "position": [0,-60,1.7], "provenance": {…}}
//! ```
//!
//! Conventions (the OpenCV ones, stated precisely):
//! - **World**: right-handed, in `units` (`m` or `BL`), z up (the 3D convention of
//!   `herdfit.tracks/1`).
//! - **Camera frame**: origin at the centre of projection, x to the image's right, y to the image's
//!   bottom, z forward along the optical axis (right-handed).
//! - **Pose**: `rotation` is the world→camera rotation R (row-major: row k is camera axis k written
//!   in world coordinates) and `position` is the camera centre C in world coordinates, so a world
//!   point X has camera coordinates `X_c = R (X − C)`.
//! - **Pixels**: `u = fx · X_c/Z_c + cx`, `v = fy · Y_c/Z_c + cy`, origin at the top-left corner of
//!   the image, u right, v down (the pixel convention of `herdfit.tracks/1`); the image covers
//!   `[0, width] × [0, height]`.
//! - **Depth** is `Z_c`, the distance along the optical axis (not along the ray). Back-projection at
//!   depth d is `X = C + d · Rᵀ [(u − cx)/fx, (v − cy)/fy, 1]`, linear in d — Lin's `Proj(p, d)`
//!   (thesis eq. 1.1).

use crate::data::tracks::Units;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of camera files.
pub const CAMERA_SCHEMA: &str = "herdfit.camera/1";

/// Tolerance of the rotation's orthonormality check (max |RRᵀ − I| entry, |det R − 1|).
const ROTATION_TOL: f64 = 1e-6;

/// A static pinhole camera; see the module docs for every convention.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Camera {
    /// Always [`CAMERA_SCHEMA`].
    pub schema: String,
    /// World length unit of `position` (and of everything lifted through this camera).
    pub units: Units,
    /// Image width and height in pixels.
    pub width: u32,
    pub height: u32,
    /// Focal lengths in pixels.
    pub fx: f64,
    pub fy: f64,
    /// Principal point in pixels (top-left origin).
    pub cx: f64,
    pub cy: f64,
    /// World→camera rotation R, row-major.
    pub rotation: [[f64; 3]; 3],
    /// Camera centre C in world coordinates.
    pub position: [f64; 3],
    /// Where the camera came from (free-form JSON).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn unit(a: V3) -> Option<V3> {
    let n = dot(a, a).sqrt();
    (n > 1e-12 && n.is_finite()).then(|| [a[0] / n, a[1] / n, a[2] / n])
}

impl Camera {
    /// A camera at `position` looking at `target`, with `up` (world) pointing to the image's top,
    /// square pixels, the principal point at the image centre and a horizontal field of view of
    /// `hfov_deg` degrees.
    pub fn look_at(
        units: Units,
        width: u32,
        height: u32,
        hfov_deg: f64,
        position: V3,
        target: V3,
        up: V3,
    ) -> Result<Camera> {
        if !(hfov_deg.is_finite() && hfov_deg > 0.0 && hfov_deg < 180.0) {
            return Err(Error::invalid(format!(
                "hfov = {hfov_deg} degrees must be in (0, 180)"
            )));
        }
        let z = unit(sub(target, position))
            .ok_or_else(|| Error::invalid("target coincides with the camera position"))?;
        let x = unit(cross(z, up))
            .ok_or_else(|| Error::invalid("up is parallel to the viewing direction"))?;
        let y = cross(z, x);
        let f = 0.5 * width as f64 / (0.5 * hfov_deg.to_radians()).tan();
        let cam = Camera {
            schema: CAMERA_SCHEMA.into(),
            units,
            width,
            height,
            fx: f,
            fy: f,
            cx: 0.5 * width as f64,
            cy: 0.5 * height as f64,
            rotation: [x, y, z],
            position,
            provenance: serde_json::Value::Null,
        };
        cam.check()?;
        Ok(cam)
    }

    /// Checks every value: schema, a world unit (not pixels), a non-empty image, finite positive
    /// focal lengths, a finite principal point and position, and a proper rotation
    /// (orthonormal, determinant +1). Errors name the key.
    pub fn check(&self) -> Result<()> {
        if self.schema != CAMERA_SCHEMA {
            return Err(Error::invalid(format!(
                "schema is '{}', expected '{CAMERA_SCHEMA}'",
                self.schema
            )));
        }
        if self.units == Units::Pixels {
            return Err(Error::invalid(
                "units = 'px': a camera's world unit must be 'm' or 'BL'",
            ));
        }
        if self.width == 0 || self.height == 0 {
            return Err(Error::invalid(format!(
                "width × height = {} × {} must be at least 1 × 1",
                self.width, self.height
            )));
        }
        for (k, v) in [("fx", self.fx), ("fy", self.fy)] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("{k} = {v} must be > 0")));
            }
        }
        for (k, v) in [("cx", self.cx), ("cy", self.cy)] {
            if !v.is_finite() {
                return Err(Error::invalid(format!("{k} = {v} must be finite")));
            }
        }
        if self.position.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("position must be finite"));
        }
        let r = &self.rotation;
        if r.iter().flatten().any(|v| !v.is_finite()) {
            return Err(Error::invalid("rotation must be finite"));
        }
        let mut worst: f64 = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { 1.0 } else { 0.0 };
                worst = worst.max((dot(r[i], r[j]) - want).abs());
            }
        }
        let det = dot(r[0], cross(r[1], r[2]));
        if worst > ROTATION_TOL || (det - 1.0).abs() > ROTATION_TOL {
            return Err(Error::invalid(format!(
                "rotation is not a rotation matrix (|RRᵀ − I| = {worst:.2e}, det = {det})"
            )));
        }
        Ok(())
    }

    /// Reads and checks a camera file.
    pub fn load(path: &Path) -> Result<Camera> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let cam: Camera = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a {CAMERA_SCHEMA} file: {e}")))?;
        cam.check().map_err(|e| e.in_file(path))?;
        Ok(cam)
    }

    /// Checks and writes the camera as JSON, atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.check().map_err(|e| e.in_file(path))?;
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Internal(format!("serialising camera: {e}")))?;
        crate::data::atomic::write_atomic(path, format!("{text}\n").as_bytes())
    }

    /// Camera coordinates `R (X − C)` of a world point.
    pub fn to_camera(&self, x: V3) -> V3 {
        let d = sub(x, self.position);
        let r = &self.rotation;
        [dot(r[0], d), dot(r[1], d), dot(r[2], d)]
    }

    /// Depth `Z_c` of a world point (negative behind the camera).
    pub fn depth(&self, x: V3) -> f64 {
        dot(self.rotation[2], sub(x, self.position))
    }

    /// Pixel `(u, v)` and depth of a world point; `None` when it is not in front of the camera.
    pub fn project(&self, x: V3) -> Option<([f64; 2], f64)> {
        let c = self.to_camera(x);
        (c[2] > 0.0).then(|| {
            (
                [
                    self.fx * c[0] / c[2] + self.cx,
                    self.fy * c[1] / c[2] + self.cy,
                ],
                c[2],
            )
        })
    }

    /// World direction of pixel `(u, v)`, scaled so that `C + d · ray` has depth d.
    pub fn ray(&self, p: [f64; 2]) -> V3 {
        let a = [(p[0] - self.cx) / self.fx, (p[1] - self.cy) / self.fy, 1.0];
        let r = &self.rotation;
        [
            r[0][0] * a[0] + r[1][0] * a[1] + r[2][0] * a[2],
            r[0][1] * a[0] + r[1][1] * a[1] + r[2][1] * a[2],
            r[0][2] * a[0] + r[1][2] * a[1] + r[2][2] * a[2],
        ]
    }

    /// The world point of pixel `p` at depth `d` (thesis eq. 1.1).
    pub fn backproject(&self, p: [f64; 2], d: f64) -> V3 {
        let r = self.ray(p);
        let c = self.position;
        [c[0] + d * r[0], c[1] + d * r[1], c[2] + d * r[2]]
    }

    /// Whether pixel `p` lies in the image `[0, width] × [0, height]`.
    pub fn in_image(&self, p: [f64; 2]) -> bool {
        p[0] >= 0.0 && p[0] <= self.width as f64 && p[1] >= 0.0 && p[1] <= self.height as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cam() -> Camera {
        Camera::look_at(
            Units::Metres,
            1280,
            720,
            60.0,
            [3.0, -40.0, 1.5],
            [0.0, 0.0, 15.0],
            [0.0, 0.0, 1.0],
        )
        .unwrap()
    }

    #[test]
    fn projection_and_backprojection_invert_each_other() {
        let c = cam();
        // The target is on the optical axis: the image centre.
        let (p, d) = c.project([0.0, 0.0, 15.0]).unwrap();
        assert!(
            (p[0] - 640.0).abs() < 1e-9 && (p[1] - 360.0).abs() < 1e-9,
            "{p:?}"
        );
        let dist = (9.0f64 + 1600.0 + 13.5 * 13.5).sqrt();
        assert!((d - dist).abs() < 1e-9);
        for x in [[5.0, 3.0, 20.0], [-7.0, 12.0, 2.0], [0.5, -30.0, 1.0]] {
            let (p, d) = c.project(x).unwrap();
            let back = c.backproject(p, d);
            for k in 0..3 {
                assert!((back[k] - x[k]).abs() < 1e-9, "{x:?} → {back:?}");
            }
            assert!((c.depth(x) - d).abs() < 1e-12);
        }
        // Up in the world is up in the image (v decreases), right is right.
        let (lo, _) = c.project([0.0, 0.0, 10.0]).unwrap();
        let (hi, _) = c.project([0.0, 0.0, 20.0]).unwrap();
        assert!(hi[1] < lo[1]);
        let (right, _) = c.project([5.0, 0.0, 15.0]).unwrap();
        assert!(right[0] > 640.0);
        assert!(c.project([3.0, -50.0, 1.5]).is_none(), "behind the camera");
        // The horizontal field of view: a point at 30° to the right lands on the right edge.
        let f = c.fx;
        assert!((f - 640.0 / (30f64).to_radians().tan()).abs() < 1e-9);
    }

    #[test]
    fn save_load_round_trip_and_bad_values_name_the_key() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("cam.json");
        let c = cam();
        c.save(&p).unwrap();
        assert_eq!(Camera::load(&p).unwrap(), c);
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("\"schema\": \"herdfit.camera/1\""));
        type Edit = Box<dyn Fn(&mut Camera)>;
        let cases: Vec<(Edit, &str)> = vec![
            (Box::new(|c| c.fx = 0.0), "fx = 0 must be > 0"),
            (Box::new(|c| c.fy = f64::NAN), "fy = NaN"),
            (Box::new(|c| c.width = 0), "width × height"),
            (Box::new(|c| c.rotation[0][0] = 2.0), "not a rotation"),
            (
                Box::new(|c| {
                    c.rotation[2] = [-c.rotation[2][0], -c.rotation[2][1], -c.rotation[2][2]]
                }),
                "not a rotation",
            ),
            (Box::new(|c| c.units = Units::Pixels), "units = 'px'"),
            (Box::new(|c| c.schema = "x".into()), "schema is 'x'"),
        ];
        for (f, want) in cases {
            let mut bad = c.clone();
            f(&mut bad);
            let e = bad.save(&p).unwrap_err().to_string();
            assert!(e.contains("cam.json") && e.contains(want), "{want}: {e}");
        }
        std::fs::write(&p, text.replace("\"fx\"", "\"focal\"")).unwrap();
        let e = Camera::load(&p).unwrap_err().to_string();
        assert!(e.contains("cam.json") && e.contains("focal"), "{e}");
    }
}
