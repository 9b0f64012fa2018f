//! Small geometric predicates used by the perception kernels.

/// A 2-D point or vector in world units (body lengths).
pub type P2 = [f64; 2];

#[inline]
fn sub(a: P2, b: P2) -> P2 {
    [a[0] - b[0], a[1] - b[1]]
}

#[inline]
fn dot(a: P2, b: P2) -> f64 {
    a[0] * b[0] + a[1] * b[1]
}

#[inline]
fn cross(a: P2, b: P2) -> f64 {
    a[0] * b[1] - a[1] * b[0]
}

/// Squared distance from point `p` to the segment `a`–`b`.
#[inline]
pub fn point_segment_dist2(p: P2, a: P2, b: P2) -> f64 {
    let ab = sub(b, a);
    let ap = sub(p, a);
    let len2 = dot(ab, ab);
    let t = if len2 > 0.0 {
        (dot(ap, ab) / len2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + t * ab[0] - p[0], a[1] + t * ab[1] - p[1]];
    dot(q, q)
}

/// Do the closed segments `p1`–`p2` and `q1`–`q2` intersect?
#[inline]
fn segments_intersect(p1: P2, p2: P2, q1: P2, q2: P2) -> bool {
    let r = sub(p2, p1);
    let s = sub(q2, q1);
    let denom = cross(r, s);
    let qp = sub(q1, p1);
    if denom.abs() < 1e-300 {
        return false; // parallel: handled by the endpoint distances
    }
    let t = cross(qp, s) / denom;
    let u = cross(qp, r) / denom;
    (0.0..=1.0).contains(&t) && (0.0..=1.0).contains(&u)
}

/// Squared distance between the segments `p1`–`p2` and `q1`–`q2`.
pub fn segment_segment_dist2(p1: P2, p2: P2, q1: P2, q2: P2) -> f64 {
    if segments_intersect(p1, p2, q1, q2) {
        return 0.0;
    }
    point_segment_dist2(p1, q1, q2)
        .min(point_segment_dist2(p2, q1, q2))
        .min(point_segment_dist2(q1, p1, p2))
        .min(point_segment_dist2(q2, p1, p2))
}

/// A body capsule: the segment `centre ± half_length · heading` swept by a disc of `radius`
/// (DESIGN §4.1).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Capsule {
    pub half_length: f64,
    pub radius: f64,
}

impl Capsule {
    /// Does the segment `a`–`b` touch the capsule of an agent at `centre` heading `heading`?
    #[inline]
    pub fn blocks(&self, a: P2, b: P2, centre: P2, heading: P2) -> bool {
        let reach = self.half_length + self.radius;
        // Cheap reject: the capsule lies within `reach` of its centre.
        if point_segment_dist2(centre, a, b) >= reach * reach {
            return false;
        }
        let e = [heading[0] * self.half_length, heading[1] * self.half_length];
        let c1 = [centre[0] - e[0], centre[1] - e[1]];
        let c2 = [centre[0] + e[0], centre[1] + e[1]];
        segment_segment_dist2(a, b, c1, c2) < self.radius * self.radius
    }
}

/// Unsigned bearing angle in `[0, π]` between the unit heading `h` and the offset `d`
/// (the atan2 form of DESIGN §4.3; never `acos`).
#[inline]
pub fn bearing(h: P2, d: P2) -> f64 {
    cross(h, d).abs().atan2(dot(h, d))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn point_segment_distance_cases() {
        assert_eq!(
            point_segment_dist2([0.0, 1.0], [-1.0, 0.0], [1.0, 0.0]),
            1.0
        );
        assert_eq!(
            point_segment_dist2([3.0, 0.0], [-1.0, 0.0], [1.0, 0.0]),
            4.0
        );
        assert_eq!(point_segment_dist2([2.0, 2.0], [0.0, 0.0], [0.0, 0.0]), 8.0);
    }

    #[test]
    fn segment_distance_crossing_parallel_and_apart() {
        assert_eq!(
            segment_segment_dist2([-1.0, 0.0], [1.0, 0.0], [0.0, -1.0], [0.0, 1.0]),
            0.0
        );
        let d = segment_segment_dist2([0.0, 0.0], [1.0, 0.0], [0.0, 0.5], [1.0, 0.5]);
        assert!((d - 0.25).abs() < 1e-15);
        let d = segment_segment_dist2([0.0, 0.0], [1.0, 0.0], [2.0, 1.0], [3.0, 1.0]);
        assert!((d - 2.0).abs() < 1e-15);
    }

    #[test]
    fn capsule_blocks_only_when_touching() {
        let cap = Capsule {
            half_length: 0.3,
            radius: 0.2,
        };
        // Body across the line of sight.
        assert!(cap.blocks([0.0, 0.0], [4.0, 0.0], [2.0, 0.1], [0.0, 1.0]));
        // Body parallel to the line of sight, 0.25 to the side: radius 0.2 misses it.
        assert!(!cap.blocks([0.0, 0.0], [4.0, 0.0], [2.0, 0.25], [1.0, 0.0]));
        // Body perpendicular, 0.45 away: the half-length 0.3 + radius 0.2 = 0.5 reaches it.
        assert!(cap.blocks([0.0, 0.0], [4.0, 0.0], [2.0, 0.45], [0.0, 1.0]));
        assert!(!cap.blocks([0.0, 0.0], [4.0, 0.0], [2.0, 0.55], [0.0, 1.0]));
    }

    #[test]
    fn bearing_range() {
        assert_eq!(bearing([1.0, 0.0], [2.0, 0.0]), 0.0);
        assert!((bearing([1.0, 0.0], [-2.0, 0.0]) - std::f64::consts::PI).abs() < 1e-15);
        assert!((bearing([1.0, 0.0], [0.0, -3.0]) - std::f64::consts::FRAC_PI_2).abs() < 1e-15);
    }
}
