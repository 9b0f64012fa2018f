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
//! k = i. Both come from one pass over the pairs ([`Pairs::eval`]): the residuals' pass keeps the
//! derivatives for the Jacobian the solver asks for next at the same y.

use super::pairs::Pairs;
use super::power;
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use std::cell::RefCell;

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
    /// Current longitudinal positions (the anchor's included; changed only through
    /// `set_params`, which keeps the cache true).
    y: Vec<f64>,
    pairs: Pairs,
    /// e and the pairs' ∂g/∂t at the current y, once evaluated.
    cache: RefCell<Option<(Vec<f64>, Vec<f64>)>>,
    /// The start y and how far from it (wingspans, any bird) the solver may go.
    leash: Option<(Vec<f64>, f64)>,
}

impl PositionProblem {
    /// A problem starting from `y0`.
    pub fn new(x: Vec<f64>, xi: Vec<f64>, anchor: usize, y0: Vec<f64>) -> Self {
        let total = power::total_abreast(&x);
        PositionProblem {
            pairs: Pairs::new(&x),
            x,
            xi,
            total,
            anchor,
            y: y0,
            cache: RefCell::new(None),
            leash: None,
        }
    }

    /// The same problem, abandoned (residuals `None`, the solver stops) as soon as an iterate
    /// moves a bird more than `d` wingspans from the start.
    pub fn with_leash(self, d: f64) -> Self {
        let y0 = self.y.clone();
        self.with_leash_around(y0, d)
    }

    /// The same problem, abandoned as soon as an iterate moves a bird more than `d` wingspans
    /// from `origin` (a continuation's last point when the solver starts from a prediction).
    pub fn with_leash_around(mut self, origin: Vec<f64>, d: f64) -> Self {
        self.leash = Some((origin, d));
        self
    }

    /// e and the pairs' ∂g/∂t at the current y (evaluated once per y).
    fn evaluated<T>(&self, f: impl FnOnce(&[f64], &[f64]) -> T) -> T {
        let mut c = self.cache.borrow_mut();
        let (e, dg) = c.get_or_insert_with(|| {
            let (mut e, mut dg) = (vec![0.0; self.x.len()], Vec::new());
            self.pairs.eval(&self.y, &mut e, &mut dg);
            (e, dg)
        });
        f(e, dg)
    }

    fn unknown(&self, k: usize) -> usize {
        if k < self.anchor {
            k
        } else {
            k - 1
        }
    }

    /// Current longitudinal positions (the anchor's included).
    pub fn y(&self) -> &[f64] {
        &self.y
    }

    /// e_i at the current y.
    pub fn savings(&self) -> Vec<f64> {
        self.evaluated(|e, _| e.to_vec())
    }

    /// Largest |ξ_i − ξ̂_i| / ξ̂_i at the current y.
    pub fn max_relative_error(&self) -> f64 {
        self.residual_vec()
            .iter()
            .map(|r| r.abs())
            .fold(0.0, f64::max)
    }

    /// The residuals r_i = (e_i / E − ξ̂_i) / ξ̂_i at the current y.
    pub fn residual_vec(&self) -> Vec<f64> {
        self.evaluated(|e, _| {
            e.iter()
                .zip(&self.xi)
                .map(|(e, xi)| (e / self.total - xi) / xi)
                .collect()
        })
    }

    /// The analytic Jacobian, N × (N − 1).
    pub fn jacobian_matrix(&self) -> DMatrix<f64> {
        let scale: Vec<f64> = self.xi.iter().map(|v| 1.0 / (self.total * v)).collect();
        self.evaluated(|_, dg| self.pairs.jacobian(dg, &scale, self.anchor))
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for PositionProblem {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, p: &DVector<f64>) {
        *self.cache.get_mut() = None;
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
        if let Some((y0, d)) = &self.leash {
            if self.y.iter().zip(y0).any(|(a, b)| (a - b).abs() > *d) {
                return None;
            }
        }
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

/// The crate's stop tolerances (ftol, xtol, gtol). A run that solves eq. 4 converges
/// quadratically, so the step after which its relative step falls below this leaves ξ at
/// rounding (|ξ − ξ̂|/ξ̂ of order 1e-14, far below `SteadyConfig::solve_tol`); at 1e-15 the crate
/// went on for 3–6 more evaluations of rounding noise before it stopped (RESULTS.md §3).
pub const STOP_TOL: f64 = 1e-12;

/// Solves eq. 4 from the problem's y by Levenberg–Marquardt (tolerances [`STOP_TOL`]), giving up
/// after `max_evaluations` residual evaluations (rounded up to a multiple of N, the crate's
/// patience unit).
pub fn solve(problem: PositionProblem, max_evaluations: usize) -> Solved {
    let n = problem.x.len().max(1);
    let lm = LevenbergMarquardt::new()
        .with_ftol(STOP_TOL)
        .with_xtol(STOP_TOL)
        .with_gtol(STOP_TOL)
        .with_patience(max_evaluations.div_ceil(n).max(1));
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
        let s = solve(PositionProblem::new(x, xi, 0, start), 200 * 15);
        assert!(s.max_relative_error < 1e-9, "{}", s.max_relative_error);
        let d =
            s.y.iter()
                .zip(&y)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
        assert!(d < 1e-6, "positions off by {d}");
    }
}
