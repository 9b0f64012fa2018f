//! Optimisers over parameter vectors (paper §6.1 and beyond): Adam, the paper's normalised step
//! and the averaged step. The state is serialisable, so a fit's checkpoint resumes exactly.
//! Model-agnostic: the caller clamps the vector to its parameters' ranges.

pub mod curvature;
pub mod multistart;

use rand::Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

/// The optimiser.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Adam (β₁ 0.9, β₂ 0.999, ε 1e-8).
    Adam,
    /// The paper's normalised gradient step θ ← θ − lr · g/‖g‖.
    Normalized,
    /// The normalised step on averaged gradients, scaled by their agreement:
    /// θ ← θ − lr · (‖m‖/√s) · m/√s, m the running mean of g (β 0.98, about one epoch of 50
    /// windows), s that of ‖g‖² (β 0.999), both bias-corrected. Where successive gradients agree
    /// it steps lr along them, as the normalised step does; where they are noise about a minimum,
    /// ‖m‖/√s falls to about 0.1 and the steps to a hundredth of lr (averaging alone would not
    /// do: the sum of averaged noise random-walks as far as the noise itself).
    Averaged,
}

enum_names!(Optimizer { Adam = "adam", Normalized = "normalized", Averaged = "averaged" });

/// Optimiser state: Adam's moments; the averaged step's mean gradient (`m`) and mean ‖g‖²
/// (`v[0]`); nothing for the normalised step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
pub struct OptState {
    pub m: Vec<f64>,
    pub v: Vec<f64>,
    pub t: u64,
}

impl OptState {
    /// The state before the first step, for a vector of `n` parameters.
    pub fn new(n: usize) -> Self {
        OptState {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }
}

/// One step of `kind` on `theta` with gradient `g` and step size `lr`. A vanishing (or not
/// finite) gradient takes `zero_grad_step` in a random direction instead (the paper's flat-region
/// rule, §6.1). An empty (default) `state` is sized to `theta` first.
pub fn step(
    kind: Optimizer,
    theta: &mut [f64],
    g: &[f64],
    state: &mut OptState,
    lr: f64,
    zero_grad_step: f64,
    rng: &mut impl Rng,
) {
    let n = theta.len();
    if state.m.is_empty() && state.v.is_empty() {
        *state = OptState::new(n);
    }
    let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm.is_nan() || norm <= 1e-12 || !norm.is_finite() {
        // Flat region (§6.1): a fixed-size step in a random direction.
        let d: Vec<f64> = (0..n).map(|_| rng.sample(StandardNormal)).collect();
        let l = d.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
        for (t, x) in theta.iter_mut().zip(d) {
            *t += zero_grad_step * x / l;
        }
        return;
    }
    match kind {
        Optimizer::Normalized => {
            for (t, x) in theta.iter_mut().zip(g) {
                *t -= lr * x / norm;
            }
        }
        Optimizer::Averaged => {
            let (b1, b2): (f64, f64) = (0.98, 0.999);
            state.t += 1;
            let (c1, c2) = (1.0 - b1.powi(state.t as i32), 1.0 - b2.powi(state.t as i32));
            // One running mean of ‖g‖² for all parameters (kept in v[0]): each parameter
            // moves by its share of the averaged gradient, as in the normalised step.
            state.v[0] = b2 * state.v[0] + (1.0 - b2) * norm * norm;
            let rms = (state.v[0] / c2).sqrt();
            for (m, x) in state.m.iter_mut().zip(g) {
                *m = b1 * *m + (1.0 - b1) * x;
            }
            // Signal-to-noise of the averaged gradient, ‖m‖/√s: 1 for a steady gradient,
            // about √((1 − β₁)/(1 + β₁)) = 0.1 for pure noise.
            let snr = state.m.iter().map(|m| (m / c1).powi(2)).sum::<f64>().sqrt() / rms;
            for (t, m) in theta.iter_mut().zip(&state.m) {
                *t -= lr * snr * (m / c1) / rms;
            }
        }
        Optimizer::Adam => {
            let (b1, b2, eps): (f64, f64, f64) = (0.9, 0.999, 1e-8);
            state.t += 1;
            let (c1, c2) = (1.0 - b1.powi(state.t as i32), 1.0 - b2.powi(state.t as i32));
            for p in 0..n {
                state.m[p] = b1 * state.m[p] + (1.0 - b1) * g[p];
                state.v[p] = b2 * state.v[p] + (1.0 - b2) * g[p] * g[p];
                theta[p] -= lr * (state.m[p] / c1) / ((state.v[p] / c2).sqrt() + eps);
            }
        }
    }
}
