//! Polygons that input files hold (scene obstacles and regions, zones, crowd layouts, an arena
//! border): the even–odd point-in-polygon test, and validation — at least three finite points, a
//! non-zero area and no edge crossing another (issue #14: a self-intersecting or zero-area
//! polygon has no inside the even–odd rule can agree on with the user).

use crate::limits::MAX_COORD;

type P2 = [f64; 2];

fn cross(o: P2, a: P2, b: P2) -> f64 {
    (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
}

/// Is `p` inside the polygon (even–odd rule)?
pub fn in_polygon(p: P2, poly: &[P2]) -> bool {
    let mut inside = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

/// Do the closed segments `a–b` and `c–d` share a point?
fn segments_meet(a: P2, b: P2, c: P2, d: P2) -> bool {
    let (d1, d2) = (cross(c, d, a), cross(c, d, b));
    let (d3, d4) = (cross(a, b, c), cross(a, b, d));
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    let on = |p: P2, q: P2, r: P2, k: f64| {
        k == 0.0
            && r[0] >= p[0].min(q[0])
            && r[0] <= p[0].max(q[0])
            && r[1] >= p[1].min(q[1])
            && r[1] <= p[1].max(q[1])
    };
    on(c, d, a, d1) || on(c, d, b, d2) || on(a, b, c, d3) || on(a, b, d, d4)
}

/// What is wrong with `poly` (crossings are looked for before the area: a bow tie's signed area
/// cancels to zero) (a closed ring, the last point joined to the first), or `None`.
pub fn polygon_problem(poly: &[P2]) -> Option<String> {
    let n = poly.len();
    if n < 3 {
        return Some(format!("a polygon needs at least 3 points, found {n}"));
    }
    if let Some((i, p)) = poly.iter().enumerate().find(|(_, p)| {
        !(p[0].is_finite() && p[1].is_finite() && p[0].abs().max(p[1].abs()) <= MAX_COORD)
    }) {
        return Some(format!(
            "point {i} ({}, {}) is not finite or beyond ±{MAX_COORD:e}",
            p[0], p[1]
        ));
    }
    // No two non-adjacent edges meet; adjacent edges meet only at their shared point.
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if a == b {
            return Some(format!("points {i} and {} are the same", (i + 1) % n));
        }
        for j in i + 1..n {
            let (c, d) = (poly[j], poly[(j + 1) % n]);
            let adjacent = j == i + 1 || (i == 0 && j == n - 1);
            if adjacent {
                // Folding back along the previous edge.
                let (p, q, r) = if j == i + 1 { (a, b, d) } else { (c, a, b) };
                if cross(p, q, r) == 0.0
                    && (q[0] - p[0]) * (r[0] - q[0]) + (q[1] - p[1]) * (r[1] - q[1]) < 0.0
                {
                    return Some(format!("edges {i} and {j} fold back onto each other"));
                }
                continue;
            }
            if segments_meet(a, b, c, d) {
                return Some(format!(
                    "edges {i} and {j} cross (the polygon intersects itself)"
                ));
            }
        }
    }
    let area2: f64 = (0..n)
        .map(|i| cross([0.0, 0.0], poly[i], poly[(i + 1) % n]))
        .sum();
    let (lo, hi) = poly.iter().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        },
    );
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]);
    if area2.abs() <= 1e-12 * span * span || span == 0.0 {
        return Some("the polygon has zero area (its points are collinear or repeated)".into());
    }
    None
}

#[cfg(test)]
mod tests {
    use super::polygon_problem;

    #[test]
    fn squares_pass_and_bow_ties_lines_and_repeats_do_not() {
        let sq = [[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]];
        assert_eq!(polygon_problem(&sq), None);
        // A concave L passes.
        let l = [
            [0.0, 0.0],
            [3.0, 0.0],
            [3.0, 1.0],
            [1.0, 1.0],
            [1.0, 3.0],
            [0.0, 3.0],
        ];
        assert_eq!(polygon_problem(&l), None);
        let bow = [[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]];
        assert!(polygon_problem(&bow).unwrap().contains("intersects itself"));
        let line = [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]];
        // Collinear points: found as an edge folding back onto another (before the zero area).
        let m = polygon_problem(&line).unwrap();
        assert!(m.contains("fold back") || m.contains("zero area"), "{m}");
        let thin = [[0.0, 0.0], [1.0, 1.0], [1.0, 1.0 + 1e-300], [0.0, 1e-300]];
        assert!(polygon_problem(&thin).is_some());
        let two = [[0.0, 0.0], [1.0, 1.0]];
        assert!(polygon_problem(&two).unwrap().contains("at least 3"));
        let nan = [[0.0, 0.0], [f64::NAN, 1.0], [2.0, 0.0]];
        assert!(polygon_problem(&nan).unwrap().contains("not finite"));
        // A vertex touching a non-adjacent edge is a self-intersection.
        let touch = [[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [2.0, 0.0], [0.0, 4.0]];
        assert!(polygon_problem(&touch)
            .unwrap()
            .contains("intersects itself"));
    }
}
