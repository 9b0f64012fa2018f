//! The CubeCL kernels of the fused force op: eq. 3–5 and their hand-written backward, the same
//! math as `herdfit_kernels::forces` (`force_on`, `agent_backward`, `pair_backward`) in f32, one
//! thread per agent walking that agent's compressed pair list.
//!
//! Branch codes (set on the CPU from the recorded perception branch): bit 0 = the right-hand
//! branch (side s = −1), bit 1 = behind the agent (σ = −1, φ offset by π), so that
//! φ = \[σ < 0\]·π + σ·atan2(s·(d × u), σ·(d · u)).
//!
//! Determinism: every thread writes only its own agent's values (or its own pairs'); the
//! contributions to a neighbour's gradient are gathered by [`forces_backward_gather`] through
//! the transposed pair list in pair order, and shared coefficients are summed by
//! [`coef_reduce`] in agent order: no atomics, so a re-run gives the same bytes.

use cubecl::prelude::*;

/// The bearing terms of one pair (the CPU kernel's `Pair`): the atan2 arguments
/// `a = s·(d × u)`, `b = σ·(d · u)`, the signs s and σ, and φ.
#[derive(CubeType, Clone, Copy)]
struct Bearing {
    a: f32,
    b: f32,
    side: f32,
    behind: f32,
    phi: f32,
}

/// The bearing of offset (dx, dy) seen from heading (hx, hy) on the branch `code`.
#[cube]
fn bearing(dx: f32, dy: f32, hx: f32, hy: f32, code: u32) -> Bearing {
    let right = f32::cast_from(code & 1u32);
    let back = f32::cast_from((code >> 1u32) & 1u32);
    let side = 1.0 - 2.0 * right;
    let behind = 1.0 - 2.0 * back;
    let a = (hx * dy - hy * dx) * side;
    let b = (hx * dx + hy * dy) * behind;
    let phi = a.atan2(b) * behind + back * core::f32::consts::PI;
    Bearing {
        a,
        b,
        side,
        behind,
        phi,
    }
}

/// One neighbour pair's terms (eq. 4): the offset u = p_j − p_i, its bearing, d², φ² and the
/// exponentials e_F = exp(α_F d² + γ_F φ²) of the forces C, V, A.
#[derive(CubeType, Clone, Copy)]
struct NbTerms {
    dx: f32,
    dy: f32,
    p: Bearing,
    d2: f32,
    phi2: f32,
    e0: f32,
    e1: f32,
    e2: f32,
}

/// [`NbTerms`] of agent i (at `(xi, yi)`, heading `(hxi, hyi)`, coefficients from `coef[c..]`)
/// and neighbour j on the branch `code`.
#[allow(clippy::too_many_arguments)]
#[cube]
fn neighbour_terms(
    x: &[f32],
    y: &[f32],
    coef: &[f32],
    c: usize,
    xi: f32,
    yi: f32,
    hxi: f32,
    hyi: f32,
    j: usize,
    code: u32,
) -> NbTerms {
    let dx = x[j] - xi;
    let dy = y[j] - yi;
    let p = bearing(dx, dy, hxi, hyi, code);
    let d2 = dx * dx + dy * dy;
    let phi2 = p.phi * p.phi;
    NbTerms {
        dx,
        dy,
        p,
        d2,
        phi2,
        e0: (coef[c + 4] * d2 + coef[c + 8] * phi2).exp(),
        e1: (coef[c + 5] * d2 + coef[c + 9] * phi2).exp(),
        e2: (coef[c + 6] * d2 + coef[c + 10] * phi2).exp(),
    }
}

/// Forward pass (eq. 3–5): `out[2i] = F_x`, `out[2i + 1] = F_y` for agent `i`. `stride` is 0 for
/// one set of coefficients shared by all agents, 12 for one set per agent.
#[allow(clippy::too_many_arguments)]
#[cube(launch)]
pub fn forces_forward_kernel(
    x: &[f32],
    y: &[f32],
    hx: &[f32],
    hy: &[f32],
    coef: &[f32],
    nb_start: &[u32],
    nb: &[u32],
    nb_code: &[u32],
    ob_start: &[u32],
    ob_xy: &[f32],
    ob_code: &[u32],
    out: &mut [f32],
    #[comptime] stride: usize,
) {
    let i = ABSOLUTE_POS;
    if i < x.len() {
        let c = i * stride;
        let xi = x[i];
        let yi = y[i];
        let hxi = hx[i];
        let hyi = hy[i];
        let mut fx = 0.0f32;
        let mut fy = 0.0f32;
        for e in nb_start[i] as usize..nb_start[i + 1] as usize {
            let j = nb[e] as usize;
            let t = neighbour_terms(x, y, coef, c, xi, yi, hxi, hyi, j, nb_code[e]);
            let cp = coef[c] * t.e0 - coef[c + 1] * t.e1;
            let ca = coef[c + 2] * t.e2;
            fx += cp * t.dx + ca * hx[j];
            fy += cp * t.dy + ca * hy[j];
        }
        for e in ob_start[i] as usize..ob_start[i + 1] as usize {
            let dx = ob_xy[2 * e] - xi;
            let dy = ob_xy[2 * e + 1] - yi;
            let p = bearing(dx, dy, hxi, hyi, ob_code[e]);
            let d2 = dx * dx + dy * dy;
            let co = coef[c + 3] * (coef[c + 7] * d2 + coef[c + 11] * p.phi * p.phi).exp();
            fx -= co * dx;
            fy -= co * dy;
        }
        out[2 * i] = fx;
        out[2 * i + 1] = fy;
    }
}

/// What the chain rule of one pair gives: the gradient on the offset (dx, dy) and agent i's
/// heading gradient.
#[derive(CubeType, Clone, Copy)]
struct PairGrad {
    dx: f32,
    dy: f32,
    hx: f32,
    hy: f32,
}

/// The chain rule of one pair through d² and φ (`pair_backward` of the CPU kernel), given the
/// sums `gd2 = Σ_F up_F c_F α_F` and `gphi2 = Σ_F up_F c_F γ_F` over the pair's forces.
#[allow(clippy::too_many_arguments)]
#[cube]
fn pair_backward(
    dx: f32,
    dy: f32,
    p: Bearing,
    gd2: f32,
    gphi2: f32,
    hxi: f32,
    hyi: f32,
) -> PairGrad {
    let r2 = p.a * p.a + p.b * p.b;
    let mut gdot = 0.0f32;
    let mut gcross = 0.0f32;
    if r2 > 0.0 {
        // φ = σ·atan2(a, b) + offset; ∂atan2/∂a = b / r², ∂atan2/∂b = −a / r².
        let gat = p.behind * 2.0 * p.phi * gphi2;
        gdot = p.behind * (-gat * p.a / r2);
        gcross = p.side * (gat * p.b / r2);
    }
    PairGrad {
        dx: 2.0 * dx * gd2 + gdot * hxi - gcross * hyi,
        dy: 2.0 * dy * gd2 + gdot * hyi + gcross * hxi,
        hx: gdot * dx + gcross * dy,
        hy: gdot * dy - gcross * dx,
    }
}

/// Adds one force's coefficient gradients (`w_F`, `α_F`, `γ_F`) of a pair to row `r` of `cg`.
#[allow(clippy::too_many_arguments)]
#[cube]
fn coef_backward(
    cg: &mut [f32],
    r: usize,
    #[comptime] f: usize,
    up: f32,
    e: f32,
    cf: f32,
    d2: f32,
    phi2: f32,
) {
    cg[r + f] += up * e;
    cg[r + 4 + f] += up * cf * d2;
    cg[r + 8 + f] += up * cf * phi2;
}

/// Backward pass, agent i's own part: from `up` (∂L/∂F laid out as the forward's output), agent
/// i's gradients on its position and heading (`own[4i..4i + 4]`: x, y, hx, hy, before its
/// neighbours' contributions), on its coefficients (`cg[12i..12i + 12]`) and what each of its
/// pairs passes to the neighbour (`to_nb[4e..4e + 4]`: x, y, hx, hy).
#[allow(clippy::too_many_arguments)]
#[cube(launch)]
pub fn forces_backward_own(
    x: &[f32],
    y: &[f32],
    hx: &[f32],
    hy: &[f32],
    coef: &[f32],
    nb_start: &[u32],
    nb: &[u32],
    nb_code: &[u32],
    ob_start: &[u32],
    ob_xy: &[f32],
    ob_code: &[u32],
    up: &[f32],
    own: &mut [f32],
    cg: &mut [f32],
    to_nb: &mut [f32],
    #[comptime] stride: usize,
) {
    let i = ABSOLUTE_POS;
    if i < x.len() {
        let c = i * stride;
        let r = 12 * i;
        let xi = x[i];
        let yi = y[i];
        let hxi = hx[i];
        let hyi = hy[i];
        let ux = up[2 * i];
        let uy = up[2 * i + 1];
        let mut gx = 0.0f32;
        let mut gy = 0.0f32;
        let mut ghx = 0.0f32;
        let mut ghy = 0.0f32;
        for k in 0..12usize {
            cg[r + k] = 0.0;
        }
        for e in nb_start[i] as usize..nb_start[i + 1] as usize {
            let j = nb[e] as usize;
            let t = neighbour_terms(x, y, coef, c, xi, yi, hxi, hyi, j, nb_code[e]);
            let c0 = coef[c] * t.e0;
            let c1 = coef[c + 1] * t.e1;
            let c2 = coef[c + 2] * t.e2;
            // F_i += (c_C − c_V)·u + c_A·d_j.
            let gu = ux * t.dx + uy * t.dy;
            let ga = ux * hx[j] + uy * hy[j];
            coef_backward(cg, r, 0usize, gu, t.e0, c0, t.d2, t.phi2);
            coef_backward(cg, r, 1usize, -gu, t.e1, c1, t.d2, t.phi2);
            coef_backward(cg, r, 2usize, ga, t.e2, c2, t.d2, t.phi2);
            let gd2 = gu * c0 * coef[c + 4] + (-gu) * c1 * coef[c + 5] + ga * c2 * coef[c + 6];
            let gphi2 = gu * c0 * coef[c + 8] + (-gu) * c1 * coef[c + 9] + ga * c2 * coef[c + 10];
            let g = pair_backward(t.dx, t.dy, t.p, gd2, gphi2, hxi, hyi);
            ghx += g.hx;
            ghy += g.hy;
            let gdx = g.dx + (c0 - c1) * ux;
            let gdy = g.dy + (c0 - c1) * uy;
            gx -= gdx;
            gy -= gdy;
            to_nb[4 * e] = gdx;
            to_nb[4 * e + 1] = gdy;
            to_nb[4 * e + 2] = c2 * ux;
            to_nb[4 * e + 3] = c2 * uy;
        }
        for e in ob_start[i] as usize..ob_start[i + 1] as usize {
            let dx = ob_xy[2 * e] - xi;
            let dy = ob_xy[2 * e + 1] - yi;
            let p = bearing(dx, dy, hxi, hyi, ob_code[e]);
            let d2 = dx * dx + dy * dy;
            let phi2 = p.phi * p.phi;
            let e3 = (coef[c + 7] * d2 + coef[c + 11] * phi2).exp();
            let c3 = coef[c + 3] * e3;
            // F_i −= c_O·(q − p_i).
            let go = -(ux * dx + uy * dy);
            coef_backward(cg, r, 3usize, go, e3, c3, d2, phi2);
            let g = pair_backward(
                dx,
                dy,
                p,
                go * c3 * coef[c + 7],
                go * c3 * coef[c + 11],
                hxi,
                hyi,
            );
            ghx += g.hx;
            ghy += g.hy;
            gx -= g.dx - c3 * ux;
            gy -= g.dy - c3 * uy;
        }
        own[4 * i] = gx;
        own[4 * i + 1] = gy;
        own[4 * i + 2] = ghx;
        own[4 * i + 3] = ghy;
    }
}

/// Backward pass, gather: agent j's gradients are its own part plus what every pair naming j
/// as the neighbour passes to it, in pair order (`tr_pair[tr_start[j]..tr_start[j + 1]]`, the
/// transposed list), written to `gx`, `gy`, `ghx`, `ghy`.
#[allow(clippy::too_many_arguments, clippy::needless_range_loop)]
#[cube(launch)]
pub fn forces_backward_gather(
    own: &[f32],
    to_nb: &[f32],
    tr_start: &[u32],
    tr_pair: &[u32],
    gx: &mut [f32],
    gy: &mut [f32],
    ghx: &mut [f32],
    ghy: &mut [f32],
) {
    let j = ABSOLUTE_POS;
    if j < gx.len() {
        let mut g0 = own[4 * j];
        let mut g1 = own[4 * j + 1];
        let mut g2 = own[4 * j + 2];
        let mut g3 = own[4 * j + 3];
        for t in tr_start[j] as usize..tr_start[j + 1] as usize {
            let e = tr_pair[t] as usize;
            g0 += to_nb[4 * e];
            g1 += to_nb[4 * e + 1];
            g2 += to_nb[4 * e + 2];
            g3 += to_nb[4 * e + 3];
        }
        gx[j] = g0;
        gy[j] = g1;
        ghx[j] = g2;
        ghy[j] = g3;
    }
}

/// Shared coefficients: `out[k] = Σ_i cg[12i + k]`, one thread per coefficient, in agent order.
#[cube(launch)]
pub fn coef_reduce(cg: &[f32], out: &mut [f32]) {
    let k = ABSOLUTE_POS;
    if k < out.len() {
        let n = cg.len() / 12;
        let mut acc = 0.0f32;
        for i in 0..n {
            acc += cg[12 * i + k];
        }
        out[k] = acc;
    }
}
