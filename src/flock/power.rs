//! Power reduction of a line formation (Klotsman & Tal §5 Step 2, eq. 1; Hummel 1983).
//!
//! Every bird is a horseshoe vortex: a bound vortex over the span π b/4 (the vortex span of an
//! elliptically loaded wing of span b) and two trailing vortices from its ends to infinity behind.
//! Positions are in wingspans in the *flock frame*: x lateral (right), y longitudinal (forward, the
//! flight direction). For birds i and j, `x = |x_j − x_i|` and `t = y_j − y_i` (positive when i
//! flies *behind* j, in j's wake). Then (the paper's formula, §5 Step 2, with signed t):
//!
//! ```text
//! (π²/2) g(x, t) = ln x²/((x − c)(x + c))
//!                 + 2 ln (x − t + r₀)/(x + t + r₀)
//!                 −   ln (x − c − t + r₋)/(x − c + t + r₋)
//!                 −   ln (x + c − t + r₊)/(x + c + t + r₊)
//!                 + [2 r₀ − r₊ − r₋] / t,          c = π/4, r_u = √(u² + t²)
//! ```
//!
//! It is the upwash of j's horseshoe (Biot–Savart) integrated over i's vortex span, divided by
//! the induced drag of a lone elliptic wing: g is the fraction of i's induced drag (and induced
//! power) that j's wake removes, so the drag ratio C of eq. 1 is 1 for induced power. The
//! derivation is in `ARCHITECTURE.md` ("Hummel's g_ij").
//!
//! [`g`] evaluates the same function in a form without cancellation: with
//! `ln((x − t + r)/(x + t + r)) = −asinh(t/x)` (x > 0) and `r_u − |u| = t²/(r_u + |u|)`,
//!
//! ```text
//! (π²/2) g = ln x²/|x² − c²| − 2 asinh(t/x) + asinh(t/|x − c|) + asinh(t/(x + c))
//!            + t [2/(r₀ + x) − 1/(r₊ + x + c) − 1/(r₋ + |x − c|)] + (2x − (x + c) − |x − c|)/t,
//! ```
//!
//! which is finite and smooth as t → 0 for x > c (birds abreast: the last term is exactly zero),
//! stays accurate for |t| ≫ x, and is the principal value of the same integral for x < c (wings
//! overlapping a neighbour's vortex, where the printed logarithms have negative arguments). The
//! odd part in t is exactly odd in floating point, so `g(x, t) + g(x, −t) = 2 g(x, 0)` holds to
//! rounding: Munk's displacement theorem ([`total_abreast`]).
//!
//! Singular set: x = 0 (one bird straight behind another: its tips on the other's vortices) and
//! x = c = π/4 (vortex cores coincident); g diverges logarithmically there.

use crate::error::{Error, Result};
use std::f64::consts::PI;

/// Spacing of the trailing vortex pair, in wingspans: π/4 (elliptic loading).
pub const VORTEX_SPAN: f64 = PI / 4.0;

/// Lateral separations closer than this to 0 or π/4 (wingspans) are refused by [`savings`].
pub const SINGULAR_MARGIN: f64 = 1e-9;

/// Hummel's g (§5 Step 2) for lateral distance `x` and longitudinal offset `t` (positive when the
/// receiving bird is behind the generating one), both in wingspans.
pub fn g(x: f64, t: f64) -> f64 {
    let c = VORTEX_SPAN;
    let a = x.abs();
    let am = (a - c).abs();
    let ap = a + c;
    let even = 2.0 * a.ln() - am.ln() - ap.ln();
    let logs = -2.0 * (t / a).asinh() + (t / am).asinh() + (t / ap).asinh();
    let (r0, rp, rm) = (a.hypot(t), ap.hypot(t), am.hypot(t));
    // 2a − (a + c) − |a − c|: exactly 0 when a ≥ c (not left to rounding).
    let d = if a >= c { 0.0 } else { 2.0 * (a - c) };
    let mut bound = t * (2.0 / (r0 + a) - 1.0 / (rp + ap) - 1.0 / (rm + am));
    if d != 0.0 {
        bound += d / t;
    }
    2.0 / (PI * PI) * (even + logs + bound)
}

/// ∂g/∂t (analytic) for the Jacobian of eq. 4.
pub fn dg_dt(x: f64, t: f64) -> f64 {
    let c = VORTEX_SPAN;
    let a = x.abs();
    let am = (a - c).abs();
    let ap = a + c;
    let (r0, rp, rm) = (a.hypot(t), ap.hypot(t), am.hypot(t));
    let logs = -2.0 / r0 + 1.0 / rm + 1.0 / rp;
    // d/dt [B/t] = (2/r₀ − 1/r₊ − 1/r₋) − B/t², with 1/r − 1/(r + u) = u/(r (r + u)).
    let mut bound = 2.0 * a / (r0 * (r0 + a)) - ap / (rp * (rp + ap)) - am / (rm * (rm + am));
    let d = if a >= c { 0.0 } else { 2.0 * (a - c) };
    if d != 0.0 {
        bound -= d / (t * t);
    }
    2.0 / (PI * PI) * (logs + bound)
}

/// The paper's printed formula, transcribed literally (for x > π/4, t ≠ 0). Kept to check [`g`]
/// against it; [`g`] is the one to use.
pub fn g_printed(x: f64, y: f64) -> f64 {
    let c = VORTEX_SPAN;
    let r = |u: f64| (u * u + y * y).sqrt();
    let v = (x * x / ((x - c) * (x + c))).ln() + 2.0 * ((x - y + r(x)) / (x + y + r(x))).ln()
        - ((x - c - y + r(x - c)) / (x - c + y + r(x - c))).ln()
        - ((x + c - y + r(x + c)) / (x + c + y + r(x + c))).ln()
        + (2.0 * r(x) - r(x + c) - r(x - c)) / y;
    2.0 / (PI * PI) * v
}

/// Checks that no two birds sit on the singular set of g (lateral separation 0 or π/4).
pub fn check_lateral(pos: &[[f64; 2]]) -> Result<()> {
    for i in 0..pos.len() {
        for j in i + 1..pos.len() {
            let a = (pos[j][0] - pos[i][0]).abs();
            if a < SINGULAR_MARGIN || (a - VORTEX_SPAN).abs() < SINGULAR_MARGIN {
                return Err(Error::invalid(format!(
                    "birds {i} and {j} are {a} wingspans apart laterally, on the singular set of \
                     Hummel's g (0 or π/4)"
                )));
            }
        }
    }
    Ok(())
}

/// Per-bird power reduction e_i = Σ_j g_ij (eq. 1 with C = 1: the fraction of the bird's
/// induced power saved), positions `[x, y]` in wingspans in the flock frame.
pub fn savings(pos: &[[f64; 2]]) -> Result<Vec<f64>> {
    check_lateral(pos)?;
    Ok(savings_unchecked(pos))
}

/// [`savings`] without the singular-set check (the caller guarantees the separations).
pub fn savings_unchecked(pos: &[[f64; 2]]) -> Vec<f64> {
    let n = pos.len();
    let mut e = vec![0.0; n];
    for i in 0..n {
        for j in 0..n {
            if i != j {
                e[i] += g(pos[j][0] - pos[i][0], pos[j][1] - pos[i][1]);
            }
        }
    }
    e
}

/// The relative values ξ_i = e_i / Σ e (§5 Step 3).
pub fn relative(e: &[f64]) -> Vec<f64> {
    let total: f64 = e.iter().sum();
    e.iter().map(|v| v / total).collect()
}

/// Σ_i e_i from the lateral positions alone: by Munk's displacement theorem the total does not
/// depend on the longitudinal positions, so it equals the total of the same birds abreast,
/// Σ_{i<j} 2 g(x_ij, 0) = Σ_{i<j} (4/π²) ln x²/|x² − c²| (eq. 3).
pub fn total_abreast(xs: &[f64]) -> f64 {
    let c2 = VORTEX_SPAN * VORTEX_SPAN;
    let mut s = 0.0;
    for i in 0..xs.len() {
        for j in i + 1..xs.len() {
            let a2 = (xs[j] - xs[i]).powi(2);
            s += (a2 / (a2 - c2).abs()).ln();
        }
    }
    4.0 / (PI * PI) * s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Upwash of a horseshoe (bound vortex over [−c/2, c/2] at t = 0, trailing vortices from its
    /// ends to t = −∞ behind the bird) at lateral X, distance `t` behind, per unit Γ/(4π).
    fn upwash(xl: f64, t: f64) -> f64 {
        let a = VORTEX_SPAN / 2.0;
        let trail = |d: f64| (1.0 + t / (t * t + d * d).sqrt()) / d;
        let bound = -((xl + a) / ((xl + a).powi(2) + t * t).sqrt()
            - (xl - a) / ((xl - a).powi(2) + t * t).sqrt())
            / t;
        trail(xl - a) - trail(xl + a) + bound
    }

    #[test]
    fn g_is_the_biot_savart_upwash_integrated_over_the_span() {
        // Gauss–Legendre-free check: composite Simpson over the receiving bird's vortex span.
        for &(x, t) in &[(1.0, 0.7), (1.3, 3.0), (2.5, 0.2), (0.9, 10.0), (1.1, -1.5)] {
            let a = VORTEX_SPAN / 2.0;
            let n = 20_000;
            let h = 2.0 * a / n as f64;
            let mut s = 0.0;
            for k in 0..=n {
                let w = if k == 0 || k == n {
                    1.0
                } else if k % 2 == 1 {
                    4.0
                } else {
                    2.0
                };
                s += w * upwash(x - a + k as f64 * h, t);
            }
            let integral = s * h / 3.0;
            // (π²/2) g = bracket = ∫ (upwash per Γ/4π) dX.
            let want = 2.0 / (PI * PI) * integral;
            assert!(
                (g(x, t) - want).abs() < 1e-9,
                "x {x} t {t}: {} vs {want}",
                g(x, t)
            );
        }
    }

    #[test]
    fn stable_form_matches_the_printed_formula_and_its_limits() {
        for &x in &[0.8, 0.9, 1.0, 1.5, 3.0, 8.0] {
            for &t in &[-20.0, -2.0, -0.3, 0.05, 0.4, 1.0, 5.0, 30.0] {
                let (a, b) = (g(x, t), g_printed(x, t));
                assert!(
                    (a - b).abs() <= 1e-9 * (1.0 + b.abs()),
                    "x {x} t {t}: {a} vs {b}"
                );
            }
            // Abreast: no 0/0; far behind: twice the abreast value; far ahead: nothing.
            let g0 = g(x, 0.0);
            assert!(g0.is_finite());
            assert!((g(x, 1e-12) - g0).abs() < 1e-10);
            assert!((g(x, 1e7) - 2.0 * g0).abs() < 1e-6 * g0);
            assert!(g(x, -1e7).abs() < 1e-6 * g0);
            let want0 = 2.0 / (PI * PI) * (x * x / (x * x - VORTEX_SPAN * VORTEX_SPAN)).ln();
            assert!((g0 - want0).abs() < 1e-14);
        }
    }

    #[test]
    fn derivative_matches_central_differences() {
        for &x in &[0.5, 0.9, 1.0, 2.0, 5.0] {
            for &t in &[-4.0, -0.5, 0.01, 0.3, 2.0, 9.0] {
                let h = 1e-6;
                let fd = (g(x, t + h) - g(x, t - h)) / (2.0 * h);
                let an = dg_dt(x, t);
                assert!(
                    (fd - an).abs() < 1e-6 * (1.0 + an.abs()),
                    "x {x} t {t}: {an} vs {fd}"
                );
            }
        }
    }

    #[test]
    fn near_the_vortex_core_g_grows_like_a_logarithm_without_nan() {
        let c = VORTEX_SPAN;
        let mut prev = 0.0;
        for k in 1..=12 {
            let x = c + 10f64.powi(-k);
            let v = g(x, 2.0);
            assert!(v.is_finite() && v > prev, "x = c + 1e-{k}: {v}");
            prev = v;
        }
        // The excess doubles per decade pair like −(4/π²) ln(x − c) behind the bird.
        let d = g(c + 1e-8, 2.0) - g(c + 1e-4, 2.0);
        assert!((d - 4.0 / (PI * PI) * (1e4f64).ln()).abs() < 1e-3, "{d}");
        assert!(check_lateral(&[[0.0, 0.0], [c, 1.0]]).is_err());
        assert!(check_lateral(&[[0.0, 0.0], [0.0, 1.0]]).is_err());
    }
}
