//! The direction variance of a cell, the clip field `dir_variance` and the S of eq. 8: the mean
//! squared angle between each animal's direction and its cell's mean direction (the sum of the
//! members' unit directions, each animal's own included). It is what the rasteriser writes for
//! tracked or simulated animals and what E_var measures on the simulated herd.
//!
//! With few animals in a cell, this quantity is well below the spread of the directions they
//! are drawn from, because each animal pulls the mean towards itself. For two animals with
//! uniformly random headings, each is half their angle away from the mean, so its expected value
//! is π²/12 ≈ 0.82 rad², not the π²/3 ≈ 3.29 rad² of a uniform direction. A still image, whose
//! user gives the *spread* of the directions (`extract --dir-variance V`, by inspection), has to
//! be written as the value this measure takes for the cell's animals: [`SampleVariance`].

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::f64::consts::PI;
use std::sync::{Arc, Mutex};

/// Largest count tabulated; above it the expected value follows the 1/n law to the spread.
const N_TABLE: usize = 32;
/// Monte Carlo draws per count (fixed seed: the same table every time).
const DRAWS: usize = 8000;

/// The expected cell direction variance of `n` animals whose directions are drawn from a wrapped
/// normal about a common direction with spread `v` — its variance about that direction, rad² —
/// or uniformly when `v` ≥ π²/3 (the largest spread a direction can have).
#[derive(Clone, Debug)]
pub struct SampleVariance {
    spread: f64,
    /// Expected value for 0, 1, …, [`N_TABLE`] animals.
    table: Vec<f64>,
}

impl SampleVariance {
    /// The table for spread `v` (rad²; negative values are taken as 0).
    pub fn new(v: f64) -> Self {
        let uniform = PI * PI / 3.0;
        let v = v.clamp(0.0, uniform);
        let sigma = (v < uniform * (1.0 - 1e-9)).then(|| sigma_of(v));
        let mut rng = ChaCha8Rng::seed_from_u64(0x5eed_d17a);
        let mut table = vec![0.0; N_TABLE + 1];
        if v > 0.0 {
            let mut th = Vec::with_capacity(N_TABLE);
            for (n, slot) in table.iter_mut().enumerate().skip(2) {
                let mut sum = 0.0;
                for _ in 0..DRAWS {
                    th.clear();
                    th.extend((0..n).map(|_| match sigma {
                        Some(s) => s * standard_normal(&mut rng),
                        None => rng.gen_range(-PI..PI),
                    }));
                    let (mx, my) = th
                        .iter()
                        .fold((0.0, 0.0), |(x, y), t| (x + t.cos(), y + t.sin()));
                    for t in &th {
                        let (hx, hy) = (t.cos(), t.sin());
                        let a = (hx * my - hy * mx).atan2(hx * mx + hy * my);
                        sum += a * a;
                    }
                }
                *slot = sum / (DRAWS * n) as f64;
            }
        }
        SampleVariance { spread: v, table }
    }

    /// The table for spread `v`, built once per spread and shared (a fit asks for it at every
    /// step).
    pub fn shared(v: f64) -> Arc<SampleVariance> {
        static TABLES: Mutex<Vec<(u64, Arc<SampleVariance>)>> = Mutex::new(Vec::new());
        let mut tables = TABLES.lock().unwrap_or_else(|e| e.into_inner());
        let key = v.to_bits();
        if let Some((_, t)) = tables.iter().find(|(k, _)| *k == key) {
            return t.clone();
        }
        let t = Arc::new(SampleVariance::new(v));
        tables.push((key, t.clone()));
        t
    }

    /// The expected cell direction variance of `n` animals (fractional counts interpolate; fewer
    /// than 2 give 0 at 1 and below, as one animal is its own mean).
    pub fn at(&self, n: f64) -> f64 {
        if n.is_nan() || n <= 1.0 {
            return 0.0;
        }
        let top = N_TABLE as f64;
        if n >= top {
            // E ≈ v − c/n: continue the last tabulated value's distance to the spread.
            return self.spread - (self.spread - self.table[N_TABLE]) * top / n;
        }
        let k = n.floor() as usize;
        let w = n - k as f64;
        (1.0 - w) * self.table[k] + w * self.table[k + 1]
    }
}

/// A standard normal draw (Box–Muller).
fn standard_normal(rng: &mut impl Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::MIN_POSITIVE..1.0);
    let u2: f64 = rng.gen_range(0.0..1.0);
    (-2.0 * u1.ln()).sqrt() * (2.0 * PI * u2).cos()
}

/// The σ of the wrapped normal whose variance about its mean direction is `v` (< π²/3), by
/// bisection on the variance computed by quadrature over the wrapped density.
fn sigma_of(v: f64) -> f64 {
    let var = |s: f64| -> f64 {
        let m = 2000;
        let (mut num, mut den) = (0.0, 0.0);
        for i in 0..m {
            let t = -PI + (i as f64 + 0.5) * 2.0 * PI / m as f64;
            let p: f64 = (-8..=8)
                .map(|k| (-(t + 2.0 * PI * k as f64).powi(2) / (2.0 * s * s)).exp())
                .sum();
            num += t * t * p;
            den += p;
        }
        num / den
    };
    let (mut lo, mut hi) = (1e-6, 20.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if var(mid) < v {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn two_random_headings_average_pi_squared_over_12_and_many_approach_the_spread() {
        let u = SampleVariance::new(PI * PI / 3.0);
        assert_eq!(u.at(1.0), 0.0);
        assert!((u.at(2.0) - PI * PI / 12.0).abs() < 0.03, "{}", u.at(2.0));
        // Increasing in the count, below the spread, and towards it for large counts.
        let vals: Vec<f64> = (2..=40).map(|n| u.at(n as f64)).collect();
        assert!(vals.windows(2).all(|w| w[0] < w[1] + 0.01), "{vals:?}");
        assert!(u.at(40.0) < PI * PI / 3.0);
        assert!((u.at(10_000.0) - PI * PI / 3.0).abs() < 0.01);
        // Fractional counts interpolate.
        let mid = u.at(2.5);
        assert!(mid > u.at(2.0) && mid < u.at(3.0));
    }

    #[test]
    fn a_narrow_spread_is_nearly_the_spread_times_the_small_sample_factor() {
        // For a small σ the angles are nearly linear: E = v (n − 1) / n.
        let v = 0.01;
        let t = SampleVariance::new(v);
        for n in [2.0, 4.0, 8.0] {
            let want = v * (n - 1.0) / n;
            assert!(
                (t.at(n) - want).abs() < 0.05 * v,
                "n {n}: {} vs {want}",
                t.at(n)
            );
        }
        assert_eq!(SampleVariance::new(0.0).at(5.0), 0.0);
        // σ of the wrapped normal for a spread of 1 rad²: close to 1 (little wrapping).
        let s = sigma_of(1.0);
        assert!((s - 1.0).abs() < 0.05, "{s}");
    }

    #[test]
    fn the_table_is_the_same_every_time() {
        let (a, b) = (SampleVariance::new(2.0), SampleVariance::new(2.0));
        assert_eq!(a.table, b.table);
    }
}
