//! The position equations of a key shape (Klotsman & Tal §5 Step 3, eq. 4), solved by
//! Levenberg–Marquardt (the `levenberg-marquardt` crate, MINPACK's algorithm on nalgebra).
//!
//! Given the lateral positions x of N birds and target relative savings ξ̂ (Σ ξ̂ = 1), find the
//! longitudinal positions y with e_i(y) = ξ̂_i E for every bird, where E = Σ e is fixed by the
//! lateral positions alone (Munk's displacement theorem, eq. 3; [`power::total_abreast`]). The
//! equations are invariant under a common shift of y, so bird `anchor` stays at its start value
//! and the other N − 1 are unknown; since Σ e_i = E for every y, the N equations hold N − 1
//! independent conditions. Residuals are relative, `r_i = (e_i / E − ξ̂_i) / ξ̂_i`, so the
//! solver's tolerance is the criterion (|ξ_i − ξ̂_i| / ξ̂_i). The Jacobian is analytic
//! ([`power::dg_dt`]): ∂e_i/∂y_k = g'(x_ik, y_k − y_i) for k ≠ i, −Σ_j g'(x_ij, y_j − y_i) for
//! k = i.

use super::power;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};

/// One instance of eq. 4.
#[derive(Clone, Debug)]
pub struct PositionProblem {
    /// Lateral positions, wingspans.
    pub x: Vec<f64>,
    /// Target relative savings ξ̂ (sum 1).
    pub xi: Vec<f64>,
    /// E = Σ e (eq. 3).
    pub total: f64,
    /// The bird whose y is held.
    pub anchor: usize,
    /// Current longitudinal positions (the anchor's included).
    pub y: Vec<f64>,
}

impl PositionProblem {
    /// A problem starting from `y0`.
    pub fn new(x: Vec<f64>, xi: Vec<f64>, anchor: usize, y0: Vec<f64>) -> Self {
        let total = power::total_abreast(&x);
        PositionProblem {
            x,
            xi,
            total,
            anchor,
            y: y0,
        }
    }

    fn unknown(&self, k: usize) -> usize {
        if k < self.anchor {
            k
        } else {
            k - 1
        }
    }

    /// e_i at the current y.
    pub fn savings(&self) -> Vec<f64> {
        let pos: Vec<[f64; 2]> = self.x.iter().zip(&self.y).map(|(&x, &y)| [x, y]).collect();
        power::savings_unchecked(&pos)
    }

    /// Largest |ξ_i − ξ̂_i| / ξ̂_i at the current y.
    pub fn max_relative_error(&self) -> f64 {
        self.residual_vec()
            .iter()
            .map(|r| r.abs())
            .fold(0.0, f64::max)
    }

    fn residual_vec(&self) -> Vec<f64> {
        self.savings()
            .iter()
            .zip(&self.xi)
            .map(|(e, xi)| (e / self.total - xi) / xi)
            .collect()
    }

    /// The analytic Jacobian, N × (N − 1).
    pub fn jacobian_matrix(&self) -> DMatrix<f64> {
        let n = self.x.len();
        let mut j = DMatrix::zeros(n, n - 1);
        for i in 0..n {
            let s = 1.0 / (self.total * self.xi[i]);
            let mut diag = 0.0;
            for k in 0..n {
                if k == i {
                    continue;
                }
                let d = power::dg_dt(self.x[k] - self.x[i], self.y[k] - self.y[i]);
                diag -= d;
                if k != self.anchor {
                    j[(i, self.unknown(k))] = d * s;
                }
            }
            if i != self.anchor {
                j[(i, self.unknown(i))] = diag * s;
            }
        }
        j
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for PositionProblem {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, p: &DVector<f64>) {
        for k in 0..self.y.len() {
            if k != self.anchor {
                self.y[k] = p[self.unknown(k)];
            }
        }
    }

    fn params(&self) -> DVector<f64> {
        DVector::from_iterator(
            self.y.len() - 1,
            (0..self.y.len())
                .filter(|&k| k != self.anchor)
                .map(|k| self.y[k]),
        )
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let r = self.residual_vec();
        r.iter()
            .all(|v| v.is_finite())
            .then(|| DVector::from_vec(r))
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let j = self.jacobian_matrix();
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}

/// Outcome of one solve.
#[derive(Clone, Debug)]
pub struct Solved {
    /// Longitudinal positions, wingspans.
    pub y: Vec<f64>,
    /// Largest relative error of ξ.
    pub max_relative_error: f64,
    /// Residual evaluations used.
    pub evaluations: usize,
}

/// Solves eq. 4 from `problem.y` by Levenberg–Marquardt (tolerances 1e-15, up to
/// `patience` × (N − 1) evaluations).
pub fn solve(problem: PositionProblem, patience: usize) -> Solved {
    let lm = LevenbergMarquardt::new()
        .with_ftol(1e-15)
        .with_xtol(1e-15)
        .with_gtol(1e-15)
        .with_patience(patience);
    let (p, report) = lm.minimize(problem);
    let err = p.max_relative_error();
    Solved {
        max_relative_error: if err.is_finite() { err } else { f64::INFINITY },
        y: p.y,
        evaluations: report.number_of_evaluations,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use levenberg_marquardt::differentiate_numerically;

    fn v_shape(n: usize) -> (Vec<f64>, Vec<f64>) {
        let x: Vec<f64> = (0..n)
            .map(|i| {
                let k = (i as f64 + 1.0) / 2.0;
                if i == 0 {
                    0.0
                } else if i % 2 == 1 {
                    -k.floor() * 1.05
                } else {
                    k.floor() * 0.98
                }
            })
            .collect();
        let y: Vec<f64> = x.iter().map(|x| -1.6 * x.abs() + 0.1 * x.sin()).collect();
        (x, y)
    }

    #[test]
    fn analytic_jacobian_matches_finite_differences() {
        let (x, y) = v_shape(9);
        let pos: Vec<[f64; 2]> = x.iter().zip(&y).map(|(&a, &b)| [a, b]).collect();
        let xi = power::relative(&power::savings(&pos).unwrap());
        let mut p = PositionProblem::new(x, xi, 0, y.iter().map(|v| v + 0.3 * v.cos()).collect());
        let an = p.jacobian().unwrap();
        let fd = differentiate_numerically(&mut p).unwrap();
        let err = (&an - &fd).abs().max();
        assert!(err < 1e-6 * an.abs().max(), "{err} of {}", an.abs().max());
    }

    #[test]
    fn recovers_a_shape_from_its_own_savings() {
        let (x, y) = v_shape(15);
        let pos: Vec<[f64; 2]> = x.iter().zip(&y).map(|(&a, &b)| [a, b]).collect();
        let xi = power::relative(&power::savings(&pos).unwrap());
        let start: Vec<f64> = y.iter().map(|v| 0.9 * v).collect();
        let s = solve(PositionProblem::new(x, xi, 0, start), 200);
        assert!(s.max_relative_error < 1e-9, "{}", s.max_relative_error);
        let d =
            s.y.iter()
                .zip(&y)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
        assert!(d < 1e-6, "positions off by {d}");
    }
}
