//! Hummel's g (Klotsman & Tal §5 Step 2, eq. 1) and ∂g/∂t for every pair of birds of a fixed
//! lateral layout, the inner loop of eq. 4's solver and of the key-shape chain (§5 Step 3).
//!
//! [`power::g`](super::power::g) splits into a part even in the longitudinal offset t, which
//! depends on the lateral distance a alone, and an odd part:
//!
//! ```text
//! (π²/2) g(a, t) = [ln a²/|a² − c²|] + [−2 asinh(t/a) + asinh(t/|a − c|) + asinh(t/(a + c))
//!                  + t w(t) + d/t],   w = 2/(r₀ + a) − 1/(r₊ + a + c) − 1/(r₋ + |a − c|),
//! (π²/2) ∂g/∂t    = −w − d/t²,        d = 2a − (a + c) − |a − c|,  r_u = √(u² + t²)
//! ```
//!
//! (∂g/∂t from [`power::dg_dt`](super::power::dg_dt) with 1/r − u/(r (r + u)) = 1/(r + u)). So for
//! the pair i < j with t = y_j − y_i, bird i (behind when t > 0) gets even + odd and bird j gets
//! even − odd, and both get the same ∂g/∂t: one evaluation serves both directions, the even part is
//! computed once per layout, asinh(t/u) = log1p(|t|/u · (1 + |t|/(u + r_u))) reuses r_u, and the
//! three asinh are one logarithm (of the product of their exponentials). Munk's theorem (eq. 3)
//! then holds by construction: the odd parts cancel pair by pair.
//!
//! The full Jacobian ∂e_i/∂y_k is symmetric: D_ik = g′ of the pair for k ≠ i, −Σ_k D_ik on the
//! diagonal.

use super::power::VORTEX_SPAN;
use nalgebra::DMatrix;
use std::f64::consts::PI;

const K: f64 = 2.0 / (PI * PI);

/// Constants of one pair of birds.
#[derive(Clone, Debug)]
struct Pair {
    i: usize,
    j: usize,
    /// a, |a − c|, a + c.
    u: [f64; 3],
    /// 1/a, 1/|a − c|, 1/(a + c).
    inv: [f64; 3],
    /// K · ln a²/|a² − c²|.
    even: f64,
    /// d = 2(a − c) for a < c, else 0.
    d: f64,
}

/// Every pair of a lateral layout `x` (wingspans), with its even part precomputed.
#[derive(Clone, Debug)]
pub struct Pairs {
    n: usize,
    pairs: Vec<Pair>,
}

impl Pairs {
    /// The pairs of lateral positions `x`; no two may be 0 or π/4 apart (the caller checks).
    pub fn new(x: &[f64]) -> Self {
        let c = VORTEX_SPAN;
        let mut pairs = Vec::with_capacity(x.len() * x.len().saturating_sub(1) / 2);
        for i in 0..x.len() {
            for j in i + 1..x.len() {
                let a = (x[j] - x[i]).abs();
                let u = [a, (a - c).abs(), a + c];
                pairs.push(Pair {
                    i,
                    j,
                    u,
                    inv: u.map(|v| 1.0 / v),
                    even: K * (2.0 * a.ln() - u[1].ln() - u[2].ln()),
                    d: if a >= c { 0.0 } else { 2.0 * (a - c) },
                });
            }
        }
        Pairs { n: x.len(), pairs }
    }

    /// Number of birds.
    pub fn len(&self) -> usize {
        self.n
    }

    /// Whether the layout has no birds.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// e_i = Σ_j g_ij (eq. 1) into `e` and, per pair in order, ∂g/∂t into `dg`.
    pub fn eval(&self, y: &[f64], e: &mut [f64], dg: &mut Vec<f64>) {
        e.iter_mut().for_each(|v| *v = 0.0);
        dg.clear();
        for p in &self.pairs {
            let t = y[p.j] - y[p.i];
            let at = t.abs();
            // asinh(|t|/u) = log1p(α_u), α_u = |t|/u · (1 + |t|/(u + r_u)); the three logarithms
            // in one: log1p(β), 1 + β = (1 + α₋)(1 + α₊)/(1 + α₀)², β formed without the 1s.
            let mut q = [0.0; 3];
            let mut al = [0.0; 3];
            for k in 0..3 {
                let u = p.u[k];
                q[k] = 1.0 / ((u * u + t * t).sqrt() + u);
                al[k] = at * p.inv[k] * (1.0 + at * q[k]);
            }
            let num = al[1] + al[2] - 2.0 * al[0] + al[1] * al[2] - al[0] * al[0];
            let logs = (num / ((1.0 + al[0]) * (1.0 + al[0]))).ln_1p();
            let w = 2.0 * q[0] - q[1] - q[2];
            let mut odd = logs.copysign(t) + t * w;
            let mut slope = -w;
            if p.d != 0.0 {
                odd += p.d / t;
                slope -= p.d / (t * t);
            }
            e[p.i] += p.even + K * odd;
            e[p.j] += p.even - K * odd;
            dg.push(K * slope);
        }
    }

    /// The N × N Jacobian ∂e_i/∂y_k from [`Pairs::eval`]'s `dg`, row i scaled by `row_scale[i]`,
    /// without column `drop` (the bird whose y is held): N × (N − 1).
    pub fn jacobian(&self, dg: &[f64], row_scale: &[f64], drop: usize) -> DMatrix<f64> {
        let n = self.n;
        let col = |k: usize| {
            if k < drop {
                Some(k)
            } else {
                (k > drop).then(|| k - 1)
            }
        };
        let mut jm = DMatrix::zeros(n, n - 1);
        let mut diag = vec![0.0; n];
        for (p, &d) in self.pairs.iter().zip(dg) {
            if let Some(cj) = col(p.j) {
                jm[(p.i, cj)] = d * row_scale[p.i];
            }
            if let Some(ci) = col(p.i) {
                jm[(p.j, ci)] = d * row_scale[p.j];
            }
            diag[p.i] -= d;
            diag[p.j] -= d;
        }
        for (i, dv) in diag.iter().enumerate() {
            if let Some(ci) = col(i) {
                jm[(i, ci)] = dv * row_scale[i];
            }
        }
        jm
    }
}

#[cfg(test)]
mod tests {
    use super::super::power;
    use super::*;

    /// A layout with gaps on both sides of π/4 (overlapping and clear wing tips) and offsets of
    /// every sign, including birds abreast (t = 0).
    fn layout() -> (Vec<f64>, Vec<f64>) {
        let x = vec![0.0, -0.83, 0.9, -1.7, 1.95, -2.6, 3.1, -3.3, 3.8];
        let y = vec![0.0, -1.2, -0.7, -2.5, -0.7, -4.0, 30.0, -3.0, 1e-9];
        (x, y)
    }

    #[test]
    fn pair_kernel_matches_hummels_g_and_its_derivative() {
        let (x, y) = layout();
        let pairs = Pairs::new(&x);
        let (mut e, mut dg) = (vec![0.0; x.len()], Vec::new());
        pairs.eval(&y, &mut e, &mut dg);
        let pos: Vec<[f64; 2]> = x.iter().zip(&y).map(|(&a, &b)| [a, b]).collect();
        let want = power::savings_unchecked(&pos);
        for (a, b) in e.iter().zip(&want) {
            assert!((a - b).abs() <= 1e-14 * (1.0 + b.abs()), "{a} vs {b}");
        }
        let jac = pairs.jacobian(&dg, &vec![1.0; x.len()], 0);
        assert_eq!((jac.nrows(), jac.ncols()), (9, 8));
        for i in 0..x.len() {
            let mut diag = 0.0;
            for k in 0..x.len() {
                if k != i {
                    let d = power::dg_dt(x[k] - x[i], y[k] - y[i]);
                    diag -= d;
                    if k > 0 {
                        let got = jac[(i, k - 1)];
                        assert!((got - d).abs() <= 1e-13 * (1.0 + d.abs()), "{i},{k}");
                    }
                }
            }
            if i > 0 {
                let got = jac[(i, i - 1)];
                assert!((got - diag).abs() <= 1e-13 * (1.0 + diag.abs()), "{i}");
            }
        }
    }

    #[test]
    fn pair_jacobian_matches_central_differences() {
        let (x, y) = layout();
        let pairs = Pairs::new(&x);
        let n = x.len();
        let (mut e, mut dg) = (vec![0.0; n], Vec::new());
        pairs.eval(&y, &mut e, &mut dg);
        let scale: Vec<f64> = (0..n).map(|i| 1.0 + i as f64).collect();
        // Hold bird 3 this time: the column dropped is not always the leader's.
        let jac = pairs.jacobian(&dg, &scale, 3);
        let h = 1e-6;
        for k in (0..n).filter(|&k| k != 3) {
            let (mut ep, mut em) = (vec![0.0; n], vec![0.0; n]);
            let mut yp = y.clone();
            yp[k] += h;
            pairs.eval(&yp, &mut ep, &mut Vec::new());
            yp[k] -= 2.0 * h;
            pairs.eval(&yp, &mut em, &mut Vec::new());
            let c = if k < 3 { k } else { k - 1 };
            for i in 0..n {
                let fd = scale[i] * (ep[i] - em[i]) / (2.0 * h);
                let an = jac[(i, c)];
                assert!(
                    (fd - an).abs() < 1e-6 * (1.0 + an.abs()),
                    "{i},{k}: {an} vs {fd}"
                );
            }
        }
    }

    #[test]
    fn odd_parts_cancel_pair_by_pair() {
        // Munk (eq. 3): Σ e does not depend on y, to rounding.
        let (x, y) = layout();
        let pairs = Pairs::new(&x);
        let mut e = vec![0.0; x.len()];
        pairs.eval(&y, &mut e, &mut Vec::new());
        let total: f64 = e.iter().sum();
        let abreast = power::total_abreast(&x);
        assert!(
            (total - abreast).abs() <= 1e-13 * abreast,
            "{total} vs {abreast}"
        );
    }
}
