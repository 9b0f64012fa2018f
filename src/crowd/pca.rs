//! Principal component analysis of the weighted states (§4: "PCA to reparameterize the state
//! space in a low-dimensional (8 to 12) space").
//!
//! The covariance of a ≤ 23-dimensional state is diagonalised with the cyclic Jacobi method: exact
//! to rounding, deterministic, and no LAPACK (ndarray 0.17 has no eigensolver of its own;
//! `linfa-reduction` needs ndarray 0.16, nalgebra 0.35 a newer Rust than this crate's 1.85, both
//! for one small symmetric matrix per model).

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// A fitted projection: `z = C (s − mean)`, `C` the `dims × input` leading eigenvectors.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Pca {
    pub mean: Vec<f64>,
    /// Row-major `dims × input`; rows are unit eigenvectors, largest eigenvalue first, each with
    /// its largest-magnitude entry positive.
    pub components: Vec<f64>,
    /// Eigenvalues (variances) of the kept components.
    pub variances: Vec<f64>,
    /// Sum of all eigenvalues (total variance).
    pub total_variance: f64,
}

impl Pca {
    /// Fits `dims` components to `n` rows of `data` (row-major, `input` columns).
    pub fn fit(data: &[f64], input: usize, dims: usize) -> Result<Pca> {
        let n = data.len() / input.max(1);
        if input == 0 || dims == 0 || dims > input {
            return Err(Error::invalid(format!(
                "pca_dims = {dims} must be in 1..={input} (the state's length)"
            )));
        }
        if n < 2 {
            return Err(Error::invalid(format!(
                "PCA needs at least 2 samples, found {n}"
            )));
        }
        let mut mean = vec![0.0; input];
        for row in data.chunks_exact(input) {
            for (m, v) in mean.iter_mut().zip(row) {
                *m += v;
            }
        }
        mean.iter_mut().for_each(|m| *m /= n as f64);
        let mut cov = vec![0.0; input * input];
        let mut c = vec![0.0; input];
        for row in data.chunks_exact(input) {
            for (ci, (v, m)) in c.iter_mut().zip(row.iter().zip(&mean)) {
                *ci = v - m;
            }
            for i in 0..input {
                for j in i..input {
                    cov[i * input + j] += c[i] * c[j];
                }
            }
        }
        for i in 0..input {
            for j in i..input {
                let v = cov[i * input + j] / (n - 1) as f64;
                cov[i * input + j] = v;
                cov[j * input + i] = v;
            }
        }
        let (vals, vecs) = jacobi_eigen(&cov, input);
        let mut order: Vec<usize> = (0..input).collect();
        order.sort_by(|&a, &b| vals[b].total_cmp(&vals[a]).then(a.cmp(&b)));
        let mut components = Vec::with_capacity(dims * input);
        for &k in order.iter().take(dims) {
            let mut col: Vec<f64> = (0..input).map(|i| vecs[i * input + k]).collect();
            let big = col
                .iter()
                .copied()
                .fold(0.0f64, |a, v| if v.abs() > a.abs() { v } else { a });
            if big < 0.0 {
                col.iter_mut().for_each(|v| *v = -*v);
            }
            components.extend(col);
        }
        Ok(Pca {
            mean,
            variances: order.iter().take(dims).map(|&k| vals[k].max(0.0)).collect(),
            total_variance: vals.iter().map(|v| v.max(0.0)).sum(),
            components,
        })
    }

    /// Input length.
    pub fn input(&self) -> usize {
        self.mean.len()
    }

    /// Output length.
    pub fn dims(&self) -> usize {
        self.variances.len()
    }

    /// Projects one state into `out` (length [`Pca::dims`]).
    pub fn project(&self, s: &[f64], out: &mut [f64]) {
        let n = self.input();
        for (o, row) in out.iter_mut().zip(self.components.chunks_exact(n)) {
            *o = row
                .iter()
                .zip(s.iter().zip(&self.mean))
                .map(|(c, (v, m))| c * (v - m))
                .sum();
        }
    }

    /// Checks the shapes (for a model read from a file).
    pub fn check(&self) -> Result<()> {
        let (n, d) = (self.input(), self.dims());
        if n == 0 || d == 0 || self.components.len() != n * d {
            return Err(Error::invalid(format!(
                "pca: components hold {} values, expected {d} × {n}",
                self.components.len()
            )));
        }
        if self
            .mean
            .iter()
            .chain(&self.components)
            .any(|v| !v.is_finite())
        {
            return Err(Error::invalid("pca: values are not finite"));
        }
        Ok(())
    }
}

/// Eigen-decomposition of a symmetric `n × n` matrix (row-major) by cyclic Jacobi rotations:
/// returns the eigenvalues and the eigenvectors as the columns of a row-major matrix.
pub fn jacobi_eigen(a: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    let mut a = a.to_vec();
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    let scale: f64 = a.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-300);
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i * n + j] * a[i * n + j])
            .sum::<f64>()
            .sqrt();
        if off <= 1e-15 * scale {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq.abs() <= 1e-300 {
                    continue;
                }
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let t = theta.signum().max(0.0) * 2.0 - 1.0;
                let t = t / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ((0..n).map(|i| a[i * n + i]).collect(), v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn jacobi_reconstructs_a_symmetric_matrix() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let n = 7;
        let mut a = vec![0.0; n * n];
        for i in 0..n {
            for j in i..n {
                let x: f64 = rng.gen_range(-1.0..1.0);
                a[i * n + j] = x;
                a[j * n + i] = x;
            }
        }
        let (w, v) = jacobi_eigen(&a, n);
        for i in 0..n {
            for j in 0..n {
                let r: f64 = (0..n).map(|k| v[i * n + k] * w[k] * v[j * n + k]).sum();
                assert!((r - a[i * n + j]).abs() < 1e-12, "{i},{j}: {r}");
                let o: f64 = (0..n).map(|k| v[k * n + i] * v[k * n + j]).sum();
                assert!((o - f64::from(u8::from(i == j))).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn pca_finds_the_long_axis_of_a_stretched_cloud() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (c, s) = (0.6f64, 0.8f64);
        let data: Vec<f64> = (0..2000)
            .flat_map(|_| {
                let (a, b): (f64, f64) = (rng.gen_range(-3.0..3.0), rng.gen_range(-0.1..0.1));
                [1.0 + c * a - s * b, -2.0 + s * a + c * b, 0.5]
            })
            .collect();
        let p = Pca::fit(&data, 3, 1).unwrap();
        assert!((p.components[0] - c).abs() < 0.01 && (p.components[1] - s).abs() < 0.01);
        assert!((p.variances[0] - 3.0).abs() < 0.2, "{}", p.variances[0]);
        // The projection is centred on the *sample* mean, which sits at a = ā along the long
        // axis (ā ≈ N(0, 3/2000), not 0): the point at a = 2 projects to 2 − ā.
        let a_bar = c * (p.mean[0] - 1.0) + s * (p.mean[1] + 2.0);
        assert!(a_bar.abs() < 0.2, "sample mean along the axis {a_bar}");
        let mut z = [0.0];
        p.project(&[1.0 + 2.0 * c, -2.0 + 2.0 * s, 0.5], &mut z);
        assert!(
            (z[0] - (2.0 - a_bar)).abs() < 0.01,
            "{z:?} vs {}",
            2.0 - a_bar
        );
        p.project(&p.mean.clone(), &mut z);
        assert!(z[0].abs() < 1e-12, "{z:?}");
        assert!(Pca::fit(&data, 3, 4).is_err());
    }
}
