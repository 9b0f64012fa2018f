//! How well a noisy objective pins down its parameters at a point (issue #15 item 2; the fit's
//! objective is paper §6.1's window loss, eq. 7–8 or field matching): the curvature from finite
//! differences of gradients with common random numbers, the noise of the gradient from the spread
//! of per-window gradients, and the sandwich covariance H⁻¹ Σ H⁻¹ that follows from them.
//!
//! The objective is a mean over windows, L(x) = (1/n) Σ_w ℓ_w(x), estimated by a *probe* that
//! returns every window's (ℓ_w, ∇ℓ_w) at x for a given random-number seed. With the same seed at
//! x ± h e_j the herds and noise are shared, so the difference of the mean gradients measures the
//! curvature, not the noise. The method, step by step:
//!
//! 1. **Curvature.** For each seed s and parameter j, H⁽ˢ⁾[:, j] = (ḡ(x + h e_j) − ḡ(x − h e_j)) /
//!    (2h), the points clamped into the box (then divided by the actual span). H is the mean over
//!    the seeds, symmetrised ((H + Hᵀ)/2: a split gradient such as the paper's, alignment from
//!    E_var, is not the gradient of one function, and its Jacobian need not be symmetric).
//! 2. **Noise.** The per-window gradients at x, averaged over the seeds window by window, are cut
//!    into B batches of consecutive windows (batch means absorb the windows' correlation in
//!    time); Σ = Cov(batch means) / B is the covariance of the objective's mean gradient, and
//!    the loss's batch means give the objective's standard error the same way.
//! 3. **Directions.** Eigen-decomposition H = V Λ Vᵀ (nalgebra's `SymmetricEigen`) over the free
//!    parameters. Each eigenvalue's own noise comes from the seeds: sd_s(v_kᵀ H⁽ˢ⁾ v_k) / √S.
//!    Along v_k the estimate's standard deviation is s_k = √(v_kᵀ Σ v_k) / λ_k (the minimiser of
//!    the estimated objective moves by −H⁻¹ δg for a gradient error δg).
//! 4. **Threshold.** A direction is *informative* when the noise is known (≥ 2 batches), λ_k > 2 ×
//!    its own noise and s_k < s_max =
//!    1/√12 (the standard deviation of a value spread uniformly over the unit range: a direction
//!    the data cannot narrow below that carries no information); it is *determined* when it is
//!    informative and 2 s_k ≤ `accuracy` (its 2-std interval lies within ± accuracy; the default
//!    0.06 is the paper's per-parameter recovery figure, §7.1.1).
//! 5. **Per parameter.** C = Σ_{k,l informative} v_k v_lᵀ (Vᵀ Σ V)_kl / (λ_k λ_l) + Σ_{k not} s_max²
//!    v_k v_kᵀ; std_i = √C_ii; a parameter is determined when 2 std_i ≤ `accuracy`.
//! 6. **Bounds.** A parameter within `bound_tol` of a bound is held there (a constrained
//!    estimate has no two-sided spread): it is left out of steps 3–5 and given a one-sided
//!    interval instead. Its curvature c comes from a one-sided difference into the box; a true
//!    value δ inside the bound would show as a mean gradient −c δ at the bound, so the data allow
//!    δ ≤ (ḡ_j + 2 σ_j) / c at the lower bound (σ_j = √Σ_jj; mirrored at the upper bound); the
//!    whole range when c ≤ 0.

use nalgebra::{DMatrix, SymmetricEigen};

/// The standard deviation of a value spread uniformly over [0, 1]: the spread reported along a
/// direction the objective does not narrow.
pub const S_MAX: f64 = 0.288_675_134_594_812_9;

/// One window's objective value and gradient.
pub type Window = (f64, Vec<f64>);

/// Settings of [`estimate`].
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    /// Finite-difference step h.
    pub step: f64,
    /// Random-number seeds (probes per point); at least 2 for the eigenvalues' noise.
    pub seeds: usize,
    /// Batches of consecutive windows for the gradient's covariance.
    pub batches: usize,
    /// A direction or parameter is determined when its 2-std half-width is at most this.
    pub accuracy: f64,
    /// A parameter this close to a bound is held at it (one-sided estimate).
    pub bound_tol: f64,
}

/// A parameter held at a bound: which, and the interval the data allow (2 std, one-sided).
#[derive(Clone, Debug, PartialEq)]
pub struct AtBound {
    pub upper: bool,
    pub within: [f64; 2],
}

/// One eigen-direction of the curvature over the free parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Direction {
    pub eigenvalue: f64,
    /// The eigenvalue's standard error across the seeds.
    pub eigenvalue_std: f64,
    /// Unit vector over all parameters (0 on those at a bound), largest component positive.
    pub vector: Vec<f64>,
    /// s_k, the estimate's standard deviation along the direction; None when not informative.
    pub std: Option<f64>,
    /// The quadratic model's minimum along the direction, −v_kᵀḡ / λ_k from the point (None when
    /// not informative): a point short of its minimum by more than 2 s_k has not converged.
    pub to_minimum: Option<f64>,
    pub determined: bool,
}

/// The estimate at a point.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Mean objective and its standard error.
    pub objective: f64,
    pub objective_std: f64,
    /// Windows per probe (the shortest seed's), batches used.
    pub windows: usize,
    pub batches: usize,
    /// Mean gradient at the point and its standard error √Σ_ii.
    pub gradient: Vec<f64>,
    pub gradient_std: Vec<f64>,
    /// The symmetrised curvature matrix (all parameters; one-sided columns at bounds).
    pub hessian: Vec<Vec<f64>>,
    /// Per parameter: std (None at a bound), determined, and the bound if held at one.
    pub std: Vec<Option<f64>>,
    pub determined: Vec<bool>,
    pub bound: Vec<Option<AtBound>>,
    /// Eigen-directions, eigenvalue decreasing.
    pub directions: Vec<Direction>,
}

/// Checks the settings; an error gives the offending field and the problem.
pub fn check(s: &Settings) -> std::result::Result<(), (&'static str, String)> {
    if !(s.step.is_finite() && s.step > 0.0 && s.step <= 0.5) {
        return Err(("step", format!("{} is out of range (0, 0.5]", s.step)));
    }
    if !(2..=64).contains(&s.seeds) {
        return Err(("seeds", format!("{} is out of range 2..=64", s.seeds)));
    }
    if !(2..=1000).contains(&s.batches) {
        return Err(("batches", format!("{} is out of range 2..=1000", s.batches)));
    }
    if !(s.accuracy.is_finite() && s.accuracy > 0.0) {
        return Err(("accuracy", format!("{} must be positive", s.accuracy)));
    }
    if !(s.bound_tol.is_finite() && s.bound_tol >= 0.0 && s.bound_tol < s.step) {
        return Err((
            "bound_tol",
            format!("{} must lie in [0, step)", s.bound_tol),
        ));
    }
    Ok(())
}

/// Probes needed for `x` in the box: per seed, the centre plus two points per free parameter and
/// one per parameter at a bound.
pub fn probes_needed(x: &[f64], lo: &[f64], hi: &[f64], s: &Settings) -> usize {
    let held = (0..x.len())
        .filter(|&j| held_at(x[j], lo[j], hi[j], s.bound_tol).is_some())
        .count();
    s.seeds * (1 + 2 * (x.len() - held) + held)
}

fn held_at(x: f64, lo: f64, hi: f64, tol: f64) -> Option<bool> {
    if x - lo <= tol {
        Some(false)
    } else if hi - x <= tol {
        Some(true)
    } else {
        None
    }
}

fn mean_gradient(ws: &[Window], n: usize) -> Vec<f64> {
    let mut g = vec![0.0; n];
    for (_, w) in ws {
        for (a, b) in g.iter_mut().zip(w) {
            *a += b / ws.len().max(1) as f64;
        }
    }
    g
}

/// Estimates the curvature, noise and determined directions of the objective behind `probe` at
/// `x` in the box [lo, hi] (see the module's method). `probe(point, seed)` returns the windows of
/// one run; the same seed must give the same random numbers.
pub fn estimate<E>(
    x: &[f64],
    lo: &[f64],
    hi: &[f64],
    s: &Settings,
    mut probe: impl FnMut(&[f64], usize) -> Result<Vec<Window>, E>,
) -> Result<Estimate, E> {
    let n = x.len();
    let bound: Vec<Option<bool>> = (0..n)
        .map(|j| held_at(x[j], lo[j], hi[j], s.bound_tol))
        .collect();
    let mut centre = Vec::with_capacity(s.seeds);
    // Per seed, the curvature's columns.
    let mut per_seed = Vec::with_capacity(s.seeds);
    for seed in 0..s.seeds {
        let c = probe(x, seed)?;
        let gc = mean_gradient(&c, n);
        let mut h = DMatrix::<f64>::zeros(n, n);
        for j in 0..n {
            let (a, b) = match bound[j] {
                None => ((x[j] - s.step).max(lo[j]), (x[j] + s.step).min(hi[j])),
                Some(false) => (x[j], (x[j] + s.step).min(hi[j])),
                Some(true) => ((x[j] - s.step).max(lo[j]), x[j]),
            };
            let at = |v: f64| {
                let mut p = x.to_vec();
                p[j] = v;
                p
            };
            let ga = if a == x[j] {
                gc.clone()
            } else {
                mean_gradient(&probe(&at(a), seed)?, n)
            };
            let gb = if b == x[j] {
                gc.clone()
            } else {
                mean_gradient(&probe(&at(b), seed)?, n)
            };
            for i in 0..n {
                h[(i, j)] = (gb[i] - ga[i]) / (b - a);
            }
        }
        per_seed.push((h.clone() + h.transpose()) * 0.5);
        centre.push(c);
    }
    Ok(assemble(x, lo, hi, s, &bound, &centre, &per_seed))
}

/// The windows averaged over the seeds window by window (up to the shortest seed's count).
fn seed_mean(centre: &[Vec<Window>], n: usize) -> Vec<Window> {
    let len = centre.iter().map(|c| c.len()).min().unwrap_or(0);
    (0..len)
        .map(|w| {
            let k = centre.len() as f64;
            let loss = centre.iter().map(|c| c[w].0).sum::<f64>() / k;
            let mut g = vec![0.0; n];
            for c in centre {
                for (a, b) in g.iter_mut().zip(&c[w].1) {
                    *a += b / k;
                }
            }
            (loss, g)
        })
        .collect()
}

/// The batch means of `ws` (B near-equal runs of consecutive windows): (loss means, gradient
/// means).
fn batch_means(ws: &[Window], batches: usize, n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let b = batches.min(ws.len()).max(1);
    let (mut losses, mut grads) = (Vec::with_capacity(b), Vec::with_capacity(b));
    for k in 0..b {
        let part = &ws[k * ws.len() / b..(k + 1) * ws.len() / b];
        losses.push(part.iter().map(|w| w.0).sum::<f64>() / part.len() as f64);
        grads.push(mean_gradient(part, n));
    }
    (losses, grads)
}

/// Sample covariance of the mean of `rows` (Cov / count).
fn covariance_of_mean(rows: &[Vec<f64>], n: usize) -> DMatrix<f64> {
    let b = rows.len();
    let mut sigma = DMatrix::<f64>::zeros(n, n);
    if b < 2 {
        return sigma;
    }
    let mean = mean_gradient(
        &rows.iter().map(|r| (0.0, r.clone())).collect::<Vec<_>>(),
        n,
    );
    for r in rows {
        for i in 0..n {
            for j in 0..n {
                sigma[(i, j)] += (r[i] - mean[i]) * (r[j] - mean[j]);
            }
        }
    }
    sigma / ((b - 1) * b) as f64
}

fn std_of_mean(v: &[f64]) -> f64 {
    let b = v.len();
    if b < 2 {
        return 0.0;
    }
    let m = v.iter().sum::<f64>() / b as f64;
    (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / ((b - 1) * b) as f64).sqrt()
}

/// Steps 2–6 of the method from the probes' results.
fn assemble(
    x: &[f64],
    lo: &[f64],
    hi: &[f64],
    s: &Settings,
    bound: &[Option<bool>],
    centre: &[Vec<Window>],
    per_seed: &[DMatrix<f64>],
) -> Estimate {
    let n = x.len();
    let windows = seed_mean(centre, n);
    let (loss_means, grad_means) = batch_means(&windows, s.batches, n);
    let sigma = covariance_of_mean(&grad_means, n);
    let gradient = mean_gradient(&windows, n);
    let h = per_seed
        .iter()
        .fold(DMatrix::<f64>::zeros(n, n), |a, b| a + b)
        / per_seed.len() as f64;
    let free: Vec<usize> = (0..n).filter(|&j| bound[j].is_none()).collect();
    // Fewer than 2 batches (a window or so) leave the noise unknown: nothing is informative.
    let noise_known = loss_means.len() >= 2;
    let (mut directions, cov) = directions(&h, &sigma, per_seed, &free, n, s, noise_known);
    for d in &mut directions {
        let along: f64 = d.vector.iter().zip(&gradient).map(|(v, g)| v * g).sum();
        d.to_minimum = d.std.map(|_| -along / d.eigenvalue);
    }
    let mut std = vec![None; n];
    let mut determined = vec![false; n];
    for &i in &free {
        let v = cov[(i, i)].max(0.0).sqrt();
        std[i] = Some(v);
        determined[i] = 2.0 * v <= s.accuracy;
    }
    let at_bound = (0..n)
        .map(|j| {
            bound[j].map(|upper| {
                let c = h[(j, j)];
                let sj = sigma[(j, j)].max(0.0).sqrt();
                // The mean gradient points out of the box at a bound that holds: + at the lower.
                let push = if upper { -gradient[j] } else { gradient[j] };
                let room = hi[j] - lo[j];
                let d = if c > 0.0 && noise_known {
                    ((push + 2.0 * sj) / c).clamp(0.0, room)
                } else {
                    room
                };
                AtBound {
                    upper,
                    within: if upper {
                        [hi[j] - d, hi[j]]
                    } else {
                        [lo[j], lo[j] + d]
                    },
                }
            })
        })
        .collect();
    Estimate {
        objective: loss_means.iter().sum::<f64>() / loss_means.len().max(1) as f64,
        objective_std: std_of_mean(&loss_means),
        windows: windows.len(),
        batches: loss_means.len(),
        gradient,
        gradient_std: (0..n).map(|i| sigma[(i, i)].max(0.0).sqrt()).collect(),
        hessian: (0..n)
            .map(|i| (0..n).map(|j| h[(i, j)]).collect())
            .collect(),
        std,
        determined,
        bound: at_bound,
        directions,
    }
}

/// Steps 3–5 over the `free` parameters: the directions and the covariance C (n × n, zero
/// outside the free block).
fn directions(
    h: &DMatrix<f64>,
    sigma: &DMatrix<f64>,
    per_seed: &[DMatrix<f64>],
    free: &[usize],
    n: usize,
    s: &Settings,
    noise_known: bool,
) -> (Vec<Direction>, DMatrix<f64>) {
    let m = free.len();
    let mut cov = DMatrix::<f64>::zeros(n, n);
    if m == 0 {
        return (Vec::new(), cov);
    }
    let sub = |a: &DMatrix<f64>| DMatrix::from_fn(m, m, |i, j| a[(free[i], free[j])]);
    let eig = SymmetricEigen::new(sub(h));
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let sig = sub(sigma);
    let seeds: Vec<DMatrix<f64>> = per_seed.iter().map(sub).collect();
    let mut vecs = Vec::with_capacity(m);
    let mut dirs = Vec::with_capacity(m);
    for &k in &order {
        let mut v = eig.eigenvectors.column(k).into_owned();
        // A deterministic sign: the largest component positive.
        let big = (0..m)
            .max_by(|&a, &b| v[a].abs().total_cmp(&v[b].abs()))
            .unwrap_or(0);
        if v[big] < 0.0 {
            v = -v;
        }
        let lambda = eig.eigenvalues[k];
        let quad = |a: &DMatrix<f64>| (v.transpose() * a * &v)[(0, 0)];
        let ls: Vec<f64> = seeds.iter().map(quad).collect();
        let lstd = sample_std(&ls) / (ls.len() as f64).sqrt();
        let sk = quad(&sig).max(0.0).sqrt() / lambda;
        let informative = noise_known && lambda > 0.0 && lambda > 2.0 * lstd && sk < S_MAX;
        let mut full = vec![0.0; n];
        for (i, &f) in free.iter().enumerate() {
            full[f] = v[i];
        }
        dirs.push(Direction {
            eigenvalue: lambda,
            eigenvalue_std: lstd,
            vector: full,
            std: informative.then_some(sk),
            to_minimum: None,
            determined: informative && 2.0 * sk <= s.accuracy,
        });
        vecs.push((v, informative, lambda));
    }
    // C in the eigenbasis: the sandwich on informative pairs, S_MAX² on the others.
    let mut c = DMatrix::<f64>::zeros(m, m);
    for (vk, ik, lk) in &vecs {
        if !*ik {
            c += vk * vk.transpose() * (S_MAX * S_MAX);
            continue;
        }
        for (vl, il, ll) in &vecs {
            if *il {
                let mkl = (vk.transpose() * &sig * vl)[(0, 0)];
                c += vk * vl.transpose() * (mkl / (lk * ll));
            }
        }
    }
    for (i, &fi) in free.iter().enumerate() {
        for (j, &fj) in free.iter().enumerate() {
            cov[(fi, fj)] = c[(i, j)];
        }
    }
    (dirs, cov)
}

fn sample_std(v: &[f64]) -> f64 {
    std_of_mean(v) * (v.len() as f64).sqrt()
}
