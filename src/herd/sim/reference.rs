//! The tensor-op reference implementation of the forces of eq. 3–5 over the padded `[N, K]`
//! lists (DESIGN §4.3, §9): the path on backends without the fused op, and what the fused op
//! ([`super::fused_forces`]) is tested against.

use super::{mat_tensor, ForceTensors, HerdState, Model, StepDecisions};
use burn::tensor::{Int, Tensor, TensorData};
use herdfit_kernels::{BRANCH_BEHIND, BRANCH_RIGHT};

impl Model {
    /// Squared distances and squared bearings `[1, n·k]` of offsets `(dx, dy)` `[n, k]` seen from
    /// headings `(hx, hy)` `[n, 1]`.
    ///
    /// The unsigned bearing φ ∈ [0, π] of eq. 4 uses atan2 (never acos) on the recorded branch
    /// (side s = ±1, behind σ = −1 / ahead σ = +1, see [`herdfit_kernels::branch_of`]):
    /// φ = [σ < 0]·π + σ·atan2(s·(h × d), σ·(h · d)). At the recorded state this equals
    /// |atan2(h × d, h · d)|; around it, it is the smooth continuation through φ = 0 and φ = π.
    /// `guard` (1 on padded entries) keeps atan2 away from (0, 0), whose gradient is NaN.
    fn distances_and_bearings(
        dx: &Tensor<2>,
        dy: &Tensor<2>,
        hx: &Tensor<2>,
        hy: &Tensor<2>,
        branch: &[u8],
        guard: Tensor<2>,
    ) -> (Tensor<2>, Tensor<2>) {
        let device = dx.device();
        let [n, k] = dx.dims();
        let side: Vec<f64> = branch
            .iter()
            .map(|&b| if b & BRANCH_RIGHT != 0 { -1.0 } else { 1.0 })
            .collect();
        let behind: Vec<f64> = branch
            .iter()
            .map(|&b| if b & BRANCH_BEHIND != 0 { -1.0 } else { 1.0 })
            .collect();
        let offset: Vec<f64> = behind
            .iter()
            .map(|&s| if s < 0.0 { std::f64::consts::PI } else { 0.0 })
            .collect();
        let side = mat_tensor(side, n, k, &device);
        let behind = mat_tensor(behind, n, k, &device);
        let offset = mat_tensor(offset, n, k, &device);
        let d2 = (dx.clone().square() + dy.clone().square()).reshape([1, n * k]);
        let dot = (hx.clone() * dx.clone() + hy.clone() * dy.clone()) * behind.clone() + guard;
        let cross = (hx.clone() * dy.clone() - hy.clone() * dx.clone()) * side;
        let phi = cross.atan2(dot) * behind + offset;
        (d2, phi.square().reshape([1, n * k]))
    }

    /// `Ω·W_F·WR_F·WA_F` (eq. 3–4) for force `g` on `[1, n·k]` pair tensors, zero on padding.
    fn pair_weight(
        f: &ForceTensors,
        g: usize,
        d2: &Tensor<2>,
        phi2: &Tensor<2>,
        mask: &Tensor<2>,
        n: usize,
    ) -> Tensor<2> {
        if f.per_agent {
            let k = d2.dims()[1] / n.max(1);
            let d2 = d2.clone().reshape([n, k]);
            let phi2 = phi2.clone().reshape([n, k]);
            ((d2 * f.alpha[g].clone() + phi2 * f.gamma[g].clone()).exp()
                * f.w[g].clone()
                * mask.clone().reshape([n, k]))
            .reshape([1, n * k])
        } else {
            (d2.clone() * f.alpha[g].clone() + phi2.clone() * f.gamma[g].clone()).exp()
                * f.w[g].clone()
                * mask.clone()
        }
    }

    /// [`Model::forces`] as tensor ops over the padded `[N, K]` lists: the reference
    /// implementation, and the path on backends without the fused op.
    pub fn reference_forces(
        f: &ForceTensors,
        s: &HerdState,
        dec: &StepDecisions,
    ) -> (Tensor<2>, Tensor<2>) {
        let device = s.x.device();
        let p = &dec.perception;
        let (n, k) = (p.n, p.k);
        let idx: Vec<i64> = p.neighbours.iter().map(|&j| j as i64).collect();
        let idx = Tensor::<1, Int>::from_data(TensorData::new(idx, [n * k]), &device);
        let maskv: Vec<f64> = p.neighbour_mask.iter().map(|&b| b as f64).collect();
        let guard = mat_tensor(maskv.iter().map(|m| 1.0 - m).collect(), n, k, &device);
        let mask = mat_tensor(maskv, 1, n * k, &device);
        let xi = s.x.clone().reshape([n, 1]);
        let yi = s.y.clone().reshape([n, 1]);
        let hxi = s.hx.clone().reshape([n, 1]);
        let hyi = s.hy.clone().reshape([n, 1]);
        let gather = |t: &Tensor<1>| t.clone().gather(0, idx.clone()).reshape([n, k]);
        let dx = gather(&s.x) - xi.clone();
        let dy = gather(&s.y) - yi.clone();
        let (d2, phi2) =
            Self::distances_and_bearings(&dx, &dy, &hxi, &hyi, &p.neighbour_branch, guard);
        let cc = Self::pair_weight(f, 0, &d2, &phi2, &mask, n);
        let cv = Self::pair_weight(f, 1, &d2, &phi2, &mask, n);
        let ca = Self::pair_weight(f, 2, &d2, &phi2, &mask, n).reshape([n, k]);
        let cp = (cc - cv).reshape([n, k]);
        let mut fx = (cp.clone() * dx + ca.clone() * gather(&s.hx)).sum_dim(1);
        let mut fy = (cp * dy + ca * gather(&s.hy)).sum_dim(1);
        if p.obstacle_mask.contains(&1) {
            let ko = p.ko;
            let om: Vec<f64> = p.obstacle_mask.iter().map(|&b| b as f64).collect();
            let oguard = mat_tensor(om.iter().map(|m| 1.0 - m).collect(), n, ko, &device);
            let omask = mat_tensor(om, 1, n * ko, &device);
            let ox = mat_tensor(
                p.obstacle_points.iter().map(|q| q[0]).collect(),
                n,
                ko,
                &device,
            );
            let oy = mat_tensor(
                p.obstacle_points.iter().map(|q| q[1]).collect(),
                n,
                ko,
                &device,
            );
            let dox = ox - xi;
            let doy = oy - yi;
            let (d2o, phi2o) =
                Self::distances_and_bearings(&dox, &doy, &hxi, &hyi, &p.obstacle_branch, oguard);
            let co = Self::pair_weight(f, 3, &d2o, &phi2o, &omask, n).reshape([n, ko]);
            fx = fx - (co.clone() * dox).sum_dim(1);
            fy = fy - (co * doy).sum_dim(1);
        }
        (fx, fy)
    }
}
