//! Hidden Point Removal (Katz, Tal & Basri 2007), the visibility operator of Klotsman & Tal §6.1,
//! in 2D and 3D: the points, seen from a viewpoint C, are *spherically flipped*,
//! p̂ = p + 2 (R − ‖p‖) p/‖p‖ (p relative to C), and a point is visible iff its flipped image is
//! a vertex of the convex hull of the flipped set and C.
//!
//! Katz et al. require the flipping sphere to contain every point; the flock paper's R = b/2 is
//! read as that sphere's margin beyond the farthest point (`R = max ‖p‖ + pad`, see
//! `ARCHITECTURE.md`). Hulls: Andrew's monotone chain in 2D (strict: collinear boundary points
//! are not vertices) and an incremental hull in 3D (coplanar input falls back to the 2D hull in
//! its plane). Both are short, exact on the inputs' own floating-point orientation tests, and need
//! no dependency; the 3D one is checked against the defining property (every point on the inner
//! side of every face) in the tests.

/// Indices of the vertices of the 2D convex hull of `pts` (counter-clockwise, strict).
pub fn hull_2d(pts: &[[f64; 2]]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..pts.len()).collect();
    idx.sort_by(|&a, &b| {
        pts[a][0]
            .total_cmp(&pts[b][0])
            .then(pts[a][1].total_cmp(&pts[b][1]))
    });
    idx.dedup_by(|a, b| pts[*a] == pts[*b]);
    if idx.len() < 3 {
        return idx;
    }
    let cross = |o: usize, a: usize, b: usize| {
        (pts[a][0] - pts[o][0]) * (pts[b][1] - pts[o][1])
            - (pts[a][1] - pts[o][1]) * (pts[b][0] - pts[o][0])
    };
    let mut hull: Vec<usize> = Vec::with_capacity(2 * idx.len());
    for pass in 0..2 {
        let start = hull.len();
        let iter: Box<dyn Iterator<Item = &usize>> = if pass == 0 {
            Box::new(idx.iter())
        } else {
            Box::new(idx.iter().rev())
        };
        for &p in iter {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], p) <= 0.0
            {
                hull.pop();
            }
            hull.push(p);
        }
        hull.pop();
    }
    hull
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn cross3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn dot3(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn norm3(a: [f64; 3]) -> f64 {
    dot3(a, a).sqrt()
}

/// Faces (outward-oriented index triples) of the 3D convex hull of `pts`, or `None` when the
/// points are coplanar (or fewer than 4).
pub fn hull_3d_faces(pts: &[[f64; 3]]) -> Option<Vec<[usize; 3]>> {
    let n = pts.len();
    if n < 4 {
        return None;
    }
    let scale = pts
        .iter()
        .map(|p| norm3(sub(*p, pts[0])))
        .fold(0.0f64, f64::max)
        .max(1e-300);
    let eps = 1e-12 * scale;
    // Initial tetrahedron: extreme points along x, the farthest from their line and plane.
    let a = (0..n).min_by(|&i, &j| pts[i][0].total_cmp(&pts[j][0]))?;
    let b = (0..n)
        .max_by(|&i, &j| norm3(sub(pts[i], pts[a])).total_cmp(&norm3(sub(pts[j], pts[a]))))?;
    let ab = sub(pts[b], pts[a]);
    let c = (0..n).max_by(|&i, &j| {
        norm3(cross3(ab, sub(pts[i], pts[a]))).total_cmp(&norm3(cross3(ab, sub(pts[j], pts[a]))))
    })?;
    let nrm = cross3(ab, sub(pts[c], pts[a]));
    if norm3(nrm) <= eps * scale {
        return None;
    }
    let d = (0..n).max_by(|&i, &j| {
        dot3(nrm, sub(pts[i], pts[a]))
            .abs()
            .total_cmp(&dot3(nrm, sub(pts[j], pts[a])).abs())
    })?;
    if dot3(nrm, sub(pts[d], pts[a])).abs() <= eps * norm3(nrm) {
        return None;
    }
    let inside = {
        let s = [pts[a], pts[b], pts[c], pts[d]];
        [0, 1, 2].map(|k| (s[0][k] + s[1][k] + s[2][k] + s[3][k]) / 4.0)
    };
    let orient = |f: [usize; 3]| -> [usize; 3] {
        let nn = cross3(sub(pts[f[1]], pts[f[0]]), sub(pts[f[2]], pts[f[0]]));
        if dot3(nn, sub(inside, pts[f[0]])) > 0.0 {
            [f[0], f[2], f[1]]
        } else {
            f
        }
    };
    let mut faces: Vec<[usize; 3]> = [[a, b, c], [a, b, d], [a, c, d], [b, c, d]]
        .into_iter()
        .map(orient)
        .collect();
    let above = |f: &[usize; 3], p: [f64; 3]| -> f64 {
        let nn = cross3(sub(pts[f[1]], pts[f[0]]), sub(pts[f[2]], pts[f[0]]));
        dot3(nn, sub(p, pts[f[0]])) / norm3(nn).max(1e-300)
    };
    for (p, &q) in pts.iter().enumerate() {
        if [a, b, c, d].contains(&p) {
            continue;
        }
        let visible: Vec<bool> = faces.iter().map(|f| above(f, q) > eps).collect();
        if !visible.iter().any(|&v| v) {
            continue;
        }
        // Horizon: directed edges of visible faces whose reverse is on a hidden face.
        let mut horizon = Vec::new();
        for (f, face) in faces.iter().enumerate() {
            if !visible[f] {
                continue;
            }
            for e in 0..3 {
                let (u, v) = (face[e], face[(e + 1) % 3]);
                let shared_hidden = faces
                    .iter()
                    .enumerate()
                    .any(|(g, h)| !visible[g] && (0..3).any(|k| h[k] == v && h[(k + 1) % 3] == u));
                if shared_hidden {
                    horizon.push((u, v));
                }
            }
        }
        let mut kept: Vec<[usize; 3]> = faces
            .iter()
            .zip(&visible)
            .filter(|(_, &v)| !v)
            .map(|(f, _)| *f)
            .collect();
        kept.extend(horizon.into_iter().map(|(u, v)| [u, v, p]));
        faces = kept;
    }
    Some(faces)
}

/// Indices of the vertices of the 3D convex hull of `pts`, ascending (coplanar input: the 2D
/// hull in its plane).
pub fn hull_3d(pts: &[[f64; 3]]) -> Vec<usize> {
    let mut v: Vec<usize> = match hull_3d_faces(pts) {
        Some(faces) => faces.iter().flatten().copied().collect(),
        None => planar_hull(pts),
    };
    v.sort_unstable();
    v.dedup();
    v
}

/// The 2D hull of coplanar (or collinear) 3D points, in coordinates of their plane.
fn planar_hull(pts: &[[f64; 3]]) -> Vec<usize> {
    if pts.len() < 3 {
        return (0..pts.len()).collect();
    }
    let o = pts[0];
    let far = (0..pts.len())
        .max_by(|&i, &j| norm3(sub(pts[i], o)).total_cmp(&norm3(sub(pts[j], o))))
        .unwrap_or(0);
    let e1 = sub(pts[far], o);
    let l1 = norm3(e1).max(1e-300);
    let e1 = e1.map(|v| v / l1);
    let mut e2 = [0.0; 3];
    for p in pts {
        let r = sub(*p, o);
        let perp = sub(r, e1.map(|v| v * dot3(r, e1)));
        if norm3(perp) > norm3(e2) {
            e2 = perp;
        }
    }
    let l2 = norm3(e2);
    let e2 = if l2 > 0.0 { e2.map(|v| v / l2) } else { e2 };
    let flat: Vec<[f64; 2]> = pts
        .iter()
        .map(|p| {
            let r = sub(*p, o);
            [dot3(r, e1), dot3(r, e2)]
        })
        .collect();
    hull_2d(&flat)
}

/// Flipping radius: the sphere through the farthest point plus `pad`.
fn radius(norms: &[f64], pad: f64) -> f64 {
    norms.iter().cloned().fold(0.0, f64::max) + pad
}

/// HPR in 2D: which of `pts` are visible from `viewpoint` (`pad` = margin of the flipping
/// sphere beyond the farthest point). Points at the viewpoint itself are not visible.
pub fn visible_2d(viewpoint: [f64; 2], pts: &[[f64; 2]], pad: f64) -> Vec<bool> {
    let rel: Vec<[f64; 2]> = pts
        .iter()
        .map(|p| [p[0] - viewpoint[0], p[1] - viewpoint[1]])
        .collect();
    let norms: Vec<f64> = rel.iter().map(|p| p[0].hypot(p[1])).collect();
    let r = radius(&norms, pad);
    let mut flipped: Vec<[f64; 2]> = rel
        .iter()
        .zip(&norms)
        .map(|(p, &l)| {
            if l > 0.0 {
                let s = (2.0 * r - l) / l;
                [p[0] * s, p[1] * s]
            } else {
                [0.0, 0.0]
            }
        })
        .collect();
    flipped.push([0.0, 0.0]);
    let mut vis = vec![false; pts.len()];
    for i in hull_2d(&flipped) {
        if i < pts.len() && norms[i] > 0.0 {
            vis[i] = true;
        }
    }
    vis
}

/// HPR in 3D (see [`visible_2d`]).
pub fn visible_3d(viewpoint: [f64; 3], pts: &[[f64; 3]], pad: f64) -> Vec<bool> {
    let rel: Vec<[f64; 3]> = pts.iter().map(|p| sub(*p, viewpoint)).collect();
    let norms: Vec<f64> = rel.iter().map(|p| norm3(*p)).collect();
    let r = radius(&norms, pad);
    let mut flipped: Vec<[f64; 3]> = rel
        .iter()
        .zip(&norms)
        .map(|(p, &l)| {
            if l > 0.0 {
                p.map(|v| v * (2.0 * r - l) / l)
            } else {
                [0.0; 3]
            }
        })
        .collect();
    flipped.push([0.0; 3]);
    let mut vis = vec![false; pts.len()];
    for i in hull_3d(&flipped) {
        if i < pts.len() && norms[i] > 0.0 {
            vis[i] = true;
        }
    }
    vis
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn hull_2d_drops_interior_and_collinear_points() {
        let pts = [
            [0.0, 0.0],
            [2.0, 0.0],
            [1.0, 0.0],
            [2.0, 2.0],
            [0.0, 2.0],
            [1.0, 1.0],
        ];
        let mut h = hull_2d(&pts);
        h.sort_unstable();
        assert_eq!(h, vec![0, 1, 3, 4]);
    }

    #[test]
    fn hull_3d_contains_every_point_and_is_a_closed_surface() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        for n in [4usize, 5, 10, 40, 100] {
            let pts: Vec<[f64; 3]> = (0..n)
                .map(|_| [rng.gen(), rng.gen(), rng.gen::<f64>() * 0.5])
                .collect();
            let faces = hull_3d_faces(&pts).unwrap();
            for f in &faces {
                let nn = cross3(sub(pts[f[1]], pts[f[0]]), sub(pts[f[2]], pts[f[0]]));
                for p in &pts {
                    assert!(dot3(nn, sub(*p, pts[f[0]])) <= 1e-9, "point outside a face");
                }
            }
            // Euler: V − E + F = 2 for a triangulated sphere (E = 3F/2).
            let v = hull_3d(&pts).len() as i64;
            let f = faces.len() as i64;
            assert_eq!(v - 3 * f / 2 + f, 2, "n {n}");
        }
        // A cube's corners plus its centre: the 8 corners.
        let mut cube: Vec<[f64; 3]> = (0..8)
            .map(|k| [(k & 1) as f64, ((k >> 1) & 1) as f64, ((k >> 2) & 1) as f64])
            .collect();
        cube.push([0.5, 0.5, 0.5]);
        assert_eq!(hull_3d(&cube), (0..8).collect::<Vec<_>>());
        // Coplanar points: the planar hull.
        let flat = [
            [0.0, 0.0, 1.0],
            [1.0, 0.0, 1.0],
            [0.0, 1.0, 1.0],
            [0.2, 0.2, 1.0],
        ];
        assert_eq!(hull_3d(&flat), vec![0, 1, 2]);
    }

    #[test]
    fn hpr_hides_points_behind_others_and_sees_a_ring() {
        // A ring around the viewer: all visible.
        let ring: Vec<[f64; 2]> = (0..12)
            .map(|k| {
                let a = k as f64 * std::f64::consts::TAU / 12.0;
                [3.0 * a.cos(), 3.0 * a.sin()]
            })
            .collect();
        assert!(visible_2d([0.0, 0.0], &ring, 0.5).iter().all(|&v| v));
        // A row of birds ahead and a bird right behind the middle one: that one is hidden.
        let pts = [[-1.0, 2.0], [0.0, 2.0], [1.0, 2.0], [0.0, 4.0], [4.0, 3.0]];
        let v = visible_2d([0.0, 0.0], &pts, 0.5);
        assert_eq!(v, vec![true, true, true, false, true]);
        // The same in 3D, lifted off the plane a little.
        let p3: Vec<[f64; 3]> = pts
            .iter()
            .enumerate()
            .map(|(i, p)| [p[0], p[1], 0.01 * i as f64])
            .collect();
        let mut p3 = p3;
        p3.extend([
            [-1.0, 2.0, 1.0],
            [1.0, 2.0, -1.0],
            [0.0, 2.0, 1.0],
            [0.0, 2.0, -1.0],
        ]);
        let v3 = visible_3d([0.0, 0.0, 0.0], &p3, 0.5);
        assert!(!v3[3], "the bird behind the middle one is hidden in 3D too");
        assert!(v3[1] && v3[4]);
    }
}
