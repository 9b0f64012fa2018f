//! Distributions of how a group moves, and distances between them: the speed, nearest-neighbour
//! distance, turning rate and polarization (eq. 12) of every agent and frame ([`MotionSamples`]),
//! compared by the 1-Wasserstein distance ([`wasserstein`]). Shared by the crowd's `compare` and
//! the herd's track evaluation.

use herdfit_kernels::P2;

/// The 1-Wasserstein distance between two empirical distributions: ∫ |F_a(x) − F_b(x)| dx.
/// NaN when either is empty.
pub fn wasserstein(a: &[f64], b: &[f64]) -> f64 {
    if a.is_empty() || b.is_empty() {
        return f64::NAN;
    }
    let mut a = a.to_vec();
    let mut b = b.to_vec();
    a.sort_by(f64::total_cmp);
    b.sort_by(f64::total_cmp);
    let (na, nb) = (a.len() as f64, b.len() as f64);
    let (mut i, mut j) = (0, 0);
    let mut x = a[0].min(b[0]);
    let mut w = 0.0;
    while i < a.len() || j < b.len() {
        let next = match (a.get(i), b.get(j)) {
            (Some(&u), Some(&v)) => u.min(v),
            (Some(&u), None) => u,
            (None, Some(&v)) => v,
            (None, None) => break,
        };
        w += (i as f64 / na - j as f64 / nb).abs() * (next - x);
        x = next;
        while i < a.len() && a[i] <= x {
            i += 1;
        }
        while j < b.len() && b[j] <= x {
            j += 1;
        }
    }
    w
}

/// Mean of a sample (NaN when empty).
pub fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Samples of the motion measures over frames.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MotionSamples {
    /// Speed (units/s) of every agent-frame with a known step.
    pub speed: Vec<f64>,
    /// Distance (units) to the nearest other agent, every agent-frame with company.
    pub nn: Vec<f64>,
    /// |change of direction| / Δt (rad/s) between two successive moving steps.
    pub turning: Vec<f64>,
    /// Polarization |Σ v̂| / N (eq. 12) of every frame with at least two moving agents.
    pub polarization: Vec<f64>,
}

impl MotionSamples {
    /// Adds one frame: each agent's position, its displacement into this frame and into the
    /// previous one (when known), the time step `dt`; steps slower than `still` units/s do not
    /// count as moving (turning rate, polarization).
    pub fn add_frame(
        &mut self,
        pos: &[P2],
        step: &[Option<P2>],
        prev: &[Option<P2>],
        dt: f64,
        still: f64,
    ) {
        let len = |v: P2| v[0].hypot(v[1]);
        let moving = |v: &Option<P2>| v.filter(|&v| len(v) > still * dt);
        let mut sum = [0.0, 0.0];
        let mut n = 0usize;
        for (i, p) in pos.iter().enumerate() {
            if let Some(d) = step[i] {
                self.speed.push(len(d) / dt);
            }
            let near = pos
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
                .fold(f64::INFINITY, f64::min);
            if near.is_finite() {
                self.nn.push(near);
            }
            if let Some(d) = moving(&step[i]) {
                if let Some(e) = moving(&prev[i]) {
                    let a = (e[0] * d[1] - e[1] * d[0]).atan2(e[0] * d[0] + e[1] * d[1]);
                    self.turning.push(a.abs() / dt);
                }
                let l = len(d);
                sum[0] += d[0] / l;
                sum[1] += d[1] / l;
                n += 1;
            }
        }
        if n >= 2 {
            self.polarization.push(sum[0].hypot(sum[1]) / n as f64);
        }
    }

    /// The four samples with their names and units (`unit` the length unit).
    pub fn named(&self, unit: &str) -> [(&'static str, String, &[f64]); 4] {
        [
            ("speed", format!("{unit}/s"), &self.speed),
            ("nearest_neighbour", unit.to_string(), &self.nn),
            ("turning_rate", "rad/s".into(), &self.turning),
            ("polarization", "1".into(), &self.polarization),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wasserstein_of_shifted_samples_is_the_shift() {
        let a = [0.0, 1.0, 2.0, 3.0];
        let b: Vec<f64> = a.iter().map(|v| v + 0.5).collect();
        assert!((wasserstein(&a, &b) - 0.5).abs() < 1e-12);
        assert_eq!(wasserstein(&a, &a), 0.0);
        // Unequal sizes: {0} vs {0, 1} → ½.
        assert!((wasserstein(&[0.0], &[0.0, 1.0]) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn a_frame_adds_speeds_distances_turns_and_polarization() {
        let mut m = MotionSamples::default();
        let pos = [[0.0, 0.0], [3.0, 4.0], [0.0, 1.0]];
        let step = [Some([0.1, 0.0]), Some([0.0, 0.1]), None];
        let prev = [Some([0.0, 0.1]), Some([0.0, 0.1]), Some([0.1, 0.0])];
        m.add_frame(&pos, &step, &prev, 0.1, 0.5);
        assert_eq!(m.speed, vec![1.0, 1.0]);
        assert_eq!(m.nn, vec![1.0, (9.0f64 + 9.0).sqrt(), 1.0]);
        let t: Vec<f64> = m.turning.iter().map(|x| (x * 1e9).round() / 1e9).collect();
        assert_eq!(
            t,
            vec![(std::f64::consts::FRAC_PI_2 / 0.1 * 1e9).round() / 1e9, 0.0]
        );
        assert!((m.polarization[0] - 0.5f64.sqrt()).abs() < 1e-12);
    }
}
