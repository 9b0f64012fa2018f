//! The whole-sequence energy of [`super::sequence`] as burn tensor ops, its gradient by burn's
//! reverse-mode autodiff: the first implementation, kept as the reference the hand-derived
//! kernel (`herdfit_kernels::lift`) is tested against (`tests/lift_gradient.rs`) and benchmarked
//! against (`benches/lift.rs`); `sequence.gradient = "autodiff"` runs the lift with it.
//!
//! Whole-array ops: every index list is one `gather` per coordinate (its backward one
//! `scatter`), so an evaluation is ≈ 60 ops whatever the size; on the ndarray backend those
//! gathers and scatters are its cost (BENCHMARKS.md, "Lift").

use super::observe::Observations;
use super::terms::{EnergyTerms, Structure};
use super::LiftConfig;
use crate::backend::cpu_device;
use crate::error::{Error, Result};
use burn::tensor::{Device, Int, Tensor, TensorData};

/// The tensors of one problem on an autodiff device.
pub(super) struct Graph {
    device: Device,
    rx: Tensor<1>,
    ry: Tensor<1>,
    rz: Tensor<1>,
    vp: Tensor<1, Int>,
    vc: Tensor<1, Int>,
    aa: Tensor<1, Int>,
    ab: Tensor<1, Int>,
    pi: Tensor<1, Int>,
    pj: Tensor<1, Int>,
    li: Tensor<1, Int>,
    lj: Tensor<1, Int>,
    has_vel: bool,
    has_acc: bool,
    has_pairs: bool,
    has_align: bool,
}

fn idx(v: impl Iterator<Item = usize>, device: &Device) -> Tensor<1, Int> {
    let v: Vec<i64> = v.map(|i| i as i64).collect();
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn vec1(v: Vec<f64>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn sum_sq(x: Tensor<1>) -> Tensor<1> {
    x.powi_scalar(2).sum()
}

/// Reads a rank-1 tensor back as f64 values.
fn read_vec(t: &Tensor<1>) -> Result<Vec<f64>> {
    t.clone()
        .try_into_vec_as::<f64>()
        .map_err(|e| Error::Internal(format!("tensor read-back failed: {e:?}")))
}

fn read1(t: Tensor<1>) -> Result<f64> {
    Ok(read_vec(&t)?.first().copied().unwrap_or(0.0))
}

impl Graph {
    /// The tensors of `obs` and `s` at the precision of `cfg.sequence.precision`.
    pub(super) fn new(obs: &Observations, s: &Structure, cfg: &LiftConfig) -> Result<Self> {
        let device = cpu_device(cfg.sequence.precision)?.autodiff();
        let comp = |k: usize| vec1(obs.ray.iter().map(|r| r[k]).collect(), &device);
        Ok(Graph {
            rx: comp(0),
            ry: comp(1),
            rz: comp(2),
            vp: idx(s.vel.iter().map(|v| v.0), &device),
            vc: idx(s.vel.iter().map(|v| v.1), &device),
            aa: idx(s.acc.iter().map(|a| a.0), &device),
            ab: idx(s.acc.iter().map(|a| a.1), &device),
            pi: idx(s.pairs.iter().map(|p| p.0), &device),
            pj: idx(s.pairs.iter().map(|p| p.1), &device),
            li: idx(s.align.iter().map(|p| p.0), &device),
            lj: idx(s.align.iter().map(|p| p.1), &device),
            has_vel: !s.vel.is_empty(),
            has_acc: !s.acc.is_empty(),
            has_pairs: !s.pairs.is_empty(),
            has_align: !s.align.is_empty(),
            device,
        })
    }

    /// The weighted terms (each a one-element tensor) at log-depths `u`.
    fn energy(&self, u: &Tensor<1>, cfg: &LiftConfig, n: usize) -> Vec<(&'static str, Tensor<1>)> {
        let w = &cfg.sequence;
        let vt = cfg.vt();
        let scale = 1.0 / n as f64;
        let d = u.clone().exp();
        let q = [
            d.clone() * self.rx.clone(),
            d.clone() * self.ry.clone(),
            d * self.rz.clone(),
        ];
        let g = |t: &Tensor<1>, i: &Tensor<1, Int>| t.clone().gather(0, i.clone());
        let mut out = Vec::new();
        if self.has_vel {
            let v: Vec<Tensor<1>> = q.iter().map(|c| g(c, &self.vc) - g(c, &self.vp)).collect();
            let sp2 = v[0].clone().powi_scalar(2)
                + v[1].clone().powi_scalar(2)
                + v[2].clone().powi_scalar(2);
            let speed = (sp2 + 1e-12 * vt * vt).sqrt();
            out.push((
                "speed",
                sum_sq(speed.clone().div_scalar(vt).sub_scalar(1.0)).mul_scalar(w.w_speed * scale),
            ));
            // Unit headings (scale-free: a flock twice as far has the same headings).
            let head: Vec<Tensor<1>> = v.iter().map(|c| c.clone() / speed.clone()).collect();
            out.push((
                "level",
                sum_sq(head[2].clone()).mul_scalar(w.w_level * scale),
            ));
            if self.has_acc {
                let a = v
                    .iter()
                    .map(|c| sum_sq(g(c, &self.ab) - g(c, &self.aa)))
                    .reduce(|x, y| x + y)
                    .expect("three components");
                out.push(("accel", a.mul_scalar(w.w_accel * scale / (vt * vt))));
            }
            if self.has_align {
                let a = head
                    .iter()
                    .map(|c| sum_sq(g(c, &self.lj) - g(c, &self.li)))
                    .reduce(|x, y| x + y)
                    .expect("three components");
                out.push(("align", a.mul_scalar(w.w_align * scale)));
            }
        }
        if self.has_pairs {
            out.push((
                "cohesion",
                sum_sq(g(u, &self.pj) - g(u, &self.pi)).mul_scalar(w.w_cohesion * scale),
            ));
            let d2 = q
                .iter()
                .map(|c| (g(c, &self.pj) - g(c, &self.pi)).powi_scalar(2))
                .reduce(|x, y| x + y)
                .expect("three components");
            let ds = cfg.d_sep;
            let dist = (d2 + 1e-12 * ds * ds).sqrt();
            let hinge = dist.div_scalar(-ds).add_scalar(1.0).clamp_min(0.0);
            out.push((
                "separation",
                sum_sq(hinge).mul_scalar(w.w_separation * scale),
            ));
        }
        out
    }

    /// The terms at log-depths `u` and, with `grad`, ∂E/∂u written into it by reverse-mode
    /// autodiff (non-finite entries as 0).
    pub(super) fn eval(
        &self,
        u: &[f64],
        cfg: &LiftConfig,
        grad: Option<&mut [f64]>,
    ) -> Result<EnergyTerms> {
        let ut = vec1(u.to_vec(), &self.device);
        let ut = if grad.is_some() {
            ut.require_grad()
        } else {
            ut
        };
        let parts = self.energy(&ut, cfg, u.len());
        let mut e = EnergyTerms::default();
        for (k, t) in &parts {
            let v = read1(t.clone().detach())?;
            match *k {
                "accel" => e.accel = v,
                "speed" => e.speed = v,
                "align" => e.align = v,
                "cohesion" => e.cohesion = v,
                "separation" => e.separation = v,
                _ => e.level = v,
            }
            e.total += v;
        }
        if let Some(out) = grad {
            let total = parts
                .into_iter()
                .map(|p| p.1)
                .reduce(|a, b| a + b)
                .ok_or_else(|| Error::Internal("empty energy".into()))?;
            let grads = total.backward();
            match ut.grad(&grads).map(|t| read_vec(&t)).transpose()? {
                Some(g) => out
                    .iter_mut()
                    .zip(g)
                    .for_each(|(o, v)| *o = if v.is_finite() { v } else { 0.0 }),
                None => out.iter_mut().for_each(|o| *o = 0.0),
            }
        }
        Ok(e)
    }
}
