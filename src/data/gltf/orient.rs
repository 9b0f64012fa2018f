//! Coordinates and orientations of the glTF export (thesis §3.6): the z-up → y-up map, the
//! smoothed headings, their quaternions and the small bird mesh.

use crate::data::tracks::Units;

type V3 = [f64; 3];

/// A tracks position in glTF coordinates (see the module docs), before `scale`.
pub fn to_gltf(units: Units, dimension: u8, p: V3) -> V3 {
    match (dimension, units) {
        (3, _) => [p[0], p[2], -p[1]],
        (_, Units::Pixels) => [p[0], 0.0, p[1]],
        _ => [p[0], 0.0, -p[1]],
    }
}

fn unit(a: V3) -> Option<V3> {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    (n > 1e-12 && n.is_finite()).then(|| a.map(|c| c / n))
}

/// Headings of one track by §3.6's smoothing (`alpha` = turn rate). Frames before the first
/// displacement take the first displacement's direction (the thesis's o² = b² − b¹); a track that
/// never moves faces +Z.
pub fn smoothed_headings(points: &[V3], alpha: f64) -> Vec<V3> {
    let mut out: Vec<Option<V3>> = Vec::with_capacity(points.len());
    let mut o: Option<V3> = None;
    for (k, p) in points.iter().enumerate() {
        if k > 0 {
            let step = [0, 1, 2].map(|c| p[c] - points[k - 1][c]);
            if let Some(s) = unit(step) {
                o = match o {
                    None => Some(s),
                    Some(prev) => {
                        unit([0, 1, 2].map(|c| (1.0 - alpha) * prev[c] + alpha * s[c])).or(Some(s))
                    }
                };
            }
        }
        out.push(o);
    }
    let first = out
        .iter()
        .flatten()
        .next()
        .copied()
        .unwrap_or([0.0, 0.0, 1.0]);
    out.into_iter().map(|h| h.unwrap_or(first)).collect()
}

/// The unit quaternion `[x, y, z, w]` turning +Z to the unit vector `h` with no roll.
pub fn heading_quaternion(h: V3) -> [f64; 4] {
    let yaw = h[0].atan2(h[2]);
    let pitch = -h[1].clamp(-1.0, 1.0).asin();
    let (sy, cy) = (0.5 * yaw).sin_cos();
    let (sx, cx) = (0.5 * pitch).sin_cos();
    [cy * sx, sy * cx, -sy * sx, cy * cx]
}

/// Rotates `v` by the unit quaternion `q = [x, y, z, w]`.
pub fn rotate(q: [f64; 4], v: V3) -> V3 {
    let u = [q[0], q[1], q[2]];
    let w = q[3];
    let cross = |a: V3, b: V3| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let t = cross(u, v).map(|c| 2.0 * c);
    let ut = cross(u, t);
    [0, 1, 2].map(|c| v[c] + w * t[c] + ut[c])
}

/// Triangles of the bird mesh for body length `l`: a body along z (nose at +z) and two swept
/// wings along ±x (span 1.8 l), flat-shaded (three vertices per face, with its normal).
pub fn bird_mesh(l: f64) -> (Vec<V3>, Vec<V3>) {
    let nose = [0.0, 0.0, 0.55 * l];
    let tail = [0.0, 0.0, -0.45 * l];
    let (w, h) = (0.09 * l, 0.08 * l);
    let ring = [[w, 0.0, 0.0], [0.0, h, 0.0], [-w, 0.0, 0.0], [0.0, -h, 0.0]];
    let mut tris: Vec<[V3; 3]> = Vec::new();
    for k in 0..4 {
        let (a, b) = (ring[k], ring[(k + 1) % 4]);
        tris.push([nose, b, a]);
        tris.push([tail, a, b]);
    }
    for s in [1.0, -1.0] {
        let root_front = [0.0, 0.0, 0.15 * l];
        let root_back = [0.0, 0.0, -0.15 * l];
        let tip = [s * 0.9 * l, 0.02 * l, -0.2 * l];
        if s > 0.0 {
            tris.push([root_front, root_back, tip]);
        } else {
            tris.push([root_front, tip, root_back]);
        }
    }
    let mut pos = Vec::new();
    let mut nor = Vec::new();
    for t in &tris {
        let e1 = [0, 1, 2].map(|c| t[1][c] - t[0][c]);
        let e2 = [0, 1, 2].map(|c| t[2][c] - t[0][c]);
        let n = unit([
            e1[1] * e2[2] - e1[2] * e2[1],
            e1[2] * e2[0] - e1[0] * e2[2],
            e1[0] * e2[1] - e1[1] * e2[0],
        ])
        .unwrap_or([0.0, 1.0, 0.0]);
        for v in t {
            pos.push(*v);
            nor.push(n);
        }
    }
    (pos, nor)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn heading_quaternion_turns_plus_z_onto_the_heading() {
        for h in [
            [1.0, 0.0, 0.0],
            [0.0, 0.0, -1.0],
            [0.6, 0.0, 0.8],
            [0.3, 0.5, -0.81],
            [0.0, 1.0, 0.0],
        ] {
            let h = unit(h).unwrap();
            let q = heading_quaternion(h);
            let r = rotate(q, [0.0, 0.0, 1.0]);
            for c in 0..3 {
                assert!((r[c] - h[c]).abs() < 1e-9, "{h:?} → {r:?}");
            }
            // No roll: the wing axis (+x) stays horizontal.
            assert!(rotate(q, [1.0, 0.0, 0.0])[1].abs() < 1e-9);
        }
    }

    #[test]
    fn headings_follow_section_3_6() {
        let pts: Vec<V3> = (0..5)
            .map(|k| [0.0, 0.0, k as f64])
            .chain([[1.0, 0.0, 4.0]])
            .collect();
        let h = smoothed_headings(&pts, 0.1);
        assert_eq!(h[0], [0.0, 0.0, 1.0]);
        assert_eq!(h[4], [0.0, 0.0, 1.0]);
        // A sharp turn to +x moves the heading by about a tenth of the way.
        let want = unit([0.1, 0.0, 0.9]).unwrap();
        for c in 0..3 {
            assert!((h[5][c] - want[c]).abs() < 1e-12);
        }
    }
}
