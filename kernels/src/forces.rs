//! The Gaussian-weighted forces of eq. 3–5 (paper §5.2, DESIGN §4.3) over compact pair lists,
//! forward and hand-written backward, as plain Rust over slices (rayon across agents).
//!
//! For agent i with position p_i and unit heading d_i, each visible neighbour j contributes
//! through the pair weight `c_F = w_F · exp(α_F d² + γ_F φ²)` (`w = Ω·W_F`, `α = −½/R_F²`,
//! `γ = −½/Φ_F²`, eq. 3–4):
//!
//! F_i = Σ_j (c_C − c_V)(p_j − p_i) + c_A d_j − Σ_o c_O (q_o − p_i)   (eq. 3 with eq. 5).
//!
//! The bearing φ ∈ [0, π] is the unsigned angle between d_i and p_j − p_i on its recorded branch
//! (side s = ±1, behind σ = ±1, see [`crate::branch_of`]):
//! φ = \[σ < 0\]·π + σ·atan2(s·(d × u), σ·(d · u)), smooth in every input around the recorded
//! state. The herd model's tensor-op path computes the same expression; this kernel is its fused
//! form: one pass per agent and no intermediate `[N, K]` arrays, and a backward pass that reads
//! the forward's φ and weight exponentials ([`PairTerms`], from [`forces_forward_keep`]) and
//! recomputes the rest of each pair's terms from the inputs (or all of them, given no terms).
//!
//! Determinism: sums run in list order per agent; contributions an agent makes to its
//! neighbours' gradients and to shared coefficients are accumulated in index order after the
//! parallel pass, so results do not depend on the thread count.

use crate::geometry::P2;
pub use crate::pairs::PairLists;
use crate::perception::{BRANCH_BEHIND, BRANCH_RIGHT};
use rayon::prelude::*;

/// Number of per-force coefficients: `w`, `α`, `γ` for each of the four forces.
pub const N_COEF: usize = 12;

/// Agents per rayon task: small herds stay on one thread, large ones split evenly.
const MIN_AGENTS_PER_TASK: usize = 256;

/// Positions and unit headings of the herd, one entry per agent.
#[derive(Clone, Copy, Debug)]
pub struct AgentsRef<'a> {
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub hx: &'a [f64],
    pub hy: &'a [f64],
}

/// Per-force coefficients `[w_C, w_V, w_A, w_O, α_C, …, α_O, γ_C, …, γ_O]`, either one set for
/// all agents (`N_COEF` values) or one per agent (`n · N_COEF`, agent-major).
#[derive(Clone, Copy, Debug)]
pub struct Coefficients<'a>(pub &'a [f64]);

impl Coefficients<'_> {
    #[inline]
    fn of(&self, i: usize) -> &[f64] {
        if self.0.len() == N_COEF {
            self.0
        } else {
            &self.0[i * N_COEF..(i + 1) * N_COEF]
        }
    }

    fn per_agent(&self) -> bool {
        self.0.len() != N_COEF
    }
}

/// The bearing terms of one pair: offset `(dx, dy)` seen from heading `(hx, hy)` on `branch`.
#[derive(Clone, Copy)]
struct Pair {
    dx: f64,
    dy: f64,
    d2: f64,
    /// `s·(h × u)` and `σ·(h · u)`: the arguments of atan2.
    a: f64,
    b: f64,
    side: f64,
    behind: f64,
    phi: f64,
}

#[inline]
fn pair(dx: f64, dy: f64, hx: f64, hy: f64, branch: u8) -> Pair {
    pair_at(dx, dy, hx, hy, branch, None)
}

/// [`pair`], with the bearing φ taken from `phi` when the forward pass kept it.
#[inline]
fn pair_at(dx: f64, dy: f64, hx: f64, hy: f64, branch: u8, phi: Option<f64>) -> Pair {
    let side = if branch & BRANCH_RIGHT != 0 {
        -1.0
    } else {
        1.0
    };
    let (behind, offset) = if branch & BRANCH_BEHIND != 0 {
        (-1.0, std::f64::consts::PI)
    } else {
        (1.0, 0.0)
    };
    let a = (hx * dy - hy * dx) * side;
    let b = (hx * dx + hy * dy) * behind;
    Pair {
        dx,
        dy,
        d2: dx * dx + dy * dy,
        a,
        b,
        side,
        behind,
        phi: phi.unwrap_or_else(|| libm::atan2(a, b) * behind + offset),
    }
}

#[inline]
fn weight(c: &[f64], g: usize, d2: f64, phi2: f64) -> (f64, f64) {
    let e = crate::fastmath::exp(c[4 + g] * d2 + c[8 + g] * phi2);
    (e, c[g] * e)
}

/// The three neighbour weights `(e_F, c_F)` for F = C, V, A (eq. 4) at once, the same bytes as
/// three calls of [`weight`].
#[inline]
fn weights3(c: &[f64], d2: f64, phi2: f64) -> ((f64, f64), (f64, f64), (f64, f64)) {
    let e = crate::fastmath::exp3([
        c[4] * d2 + c[8] * phi2,
        c[5] * d2 + c[9] * phi2,
        c[6] * d2 + c[10] * phi2,
    ]);
    (
        (e[0], c[0] * e[0]),
        (e[1], c[1] * e[1]),
        (e[2], c[2] * e[2]),
    )
}

/// The pair terms a forward pass keeps for its backward pass: for each agent–neighbour pair
/// `[φ, e_C, e_V, e_A]` and for each obstacle point `[φ, e_O]`, with `e_F = exp(α_F d² + γ_F φ²)`
/// (eq. 4), in pair-list order. With them the backward pass evaluates no `exp` or `atan2`; the
/// values are those it would recompute, so the gradients have the same bytes.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PairTerms {
    pub nb: Vec<[f64; 4]>,
    pub ob: Vec<[f64; 2]>,
}

/// Where [`force_on`] writes one agent's pair terms (`None`: keep nothing).
type Keep<'a> = Option<(&'a mut [[f64; 4]], &'a mut [[f64; 2]])>;

/// The force on agent `i` (eq. 3), in list order.
#[inline]
fn force_on(
    i: usize,
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    mut keep: Keep<'_>,
) -> P2 {
    let c = coef.of(i);
    let (xi, yi, hxi, hyi) = (s.x[i], s.y[i], s.hx[i], s.hy[i]);
    let (mut fx, mut fy) = (0.0, 0.0);
    for (k, e) in lists.neighbours(i).enumerate() {
        let j = lists.nb[e] as usize;
        let p = pair(s.x[j] - xi, s.y[j] - yi, hxi, hyi, lists.nb_branch[e]);
        let phi2 = p.phi * p.phi;
        let (w0, w1, w2) = weights3(c, p.d2, phi2);
        if let Some((nb, _)) = keep.as_mut() {
            nb[k] = [p.phi, w0.0, w1.0, w2.0];
        }
        let cp = w0.1 - w1.1;
        let ca = w2.1;
        fx += cp * p.dx + ca * s.hx[j];
        fy += cp * p.dy + ca * s.hy[j];
    }
    for (k, e) in lists.obstacles(i).enumerate() {
        let q = lists.ob_point[e];
        let p = pair(q[0] - xi, q[1] - yi, hxi, hyi, lists.ob_branch[e]);
        let (e3, co) = weight(c, 3, p.d2, p.phi * p.phi);
        if let Some((_, ob)) = keep.as_mut() {
            ob[k] = [p.phi, e3];
        }
        fx -= co * p.dx;
        fy -= co * p.dy;
    }
    [fx, fy]
}

/// Splits `v` (one entry per pair, in list order) at agent boundaries: agent i gets
/// `start[i]..start[i + 1]`.
fn per_agent<'a, T>(mut v: &'a mut [T], start: &[u32]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(start.len().saturating_sub(1));
    for w in start.windows(2) {
        let (head, tail) = v.split_at_mut((w[1] - w[0]) as usize);
        out.push(head);
        v = tail;
    }
    out
}

/// Forward pass: the force of eq. 3 on every agent, written as `out[2i] = F_x`, `out[2i+1] = F_y`.
pub fn forces_forward(
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    out: &mut [f64],
) {
    assert_eq!(
        out.len(),
        2 * lists.n,
        "forces_forward: out must hold 2·n values"
    );
    out.par_chunks_mut(2)
        .with_min_len(MIN_AGENTS_PER_TASK)
        .enumerate()
        .for_each(|(i, f)| {
            let v = force_on(i, lists, s, coef, None);
            f[0] = v[0];
            f[1] = v[1];
        });
}

/// [`forces_forward`], also returning the pair terms for [`forces_backward`] (the same forces,
/// byte for byte).
pub fn forces_forward_keep(
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    out: &mut [f64],
) -> PairTerms {
    assert_eq!(
        out.len(),
        2 * lists.n,
        "forces_forward_keep: out must hold 2·n values"
    );
    let mut terms = PairTerms {
        nb: vec![[0.0; 4]; lists.pairs()],
        ob: vec![[0.0; 2]; lists.ob_point.len()],
    };
    let nb = per_agent(&mut terms.nb, &lists.nb_start);
    let ob = per_agent(&mut terms.ob, &lists.ob_start);
    out.par_chunks_mut(2)
        .zip(nb)
        .zip(ob)
        .with_min_len(MIN_AGENTS_PER_TASK)
        .enumerate()
        .for_each(|(i, ((f, nb), ob))| {
            let v = force_on(i, lists, s, coef, Some((nb, ob)));
            f[0] = v[0];
            f[1] = v[1];
        });
    terms
}

/// Gradients of a scalar loss with respect to every input of [`forces_forward`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ForceGrads {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub hx: Vec<f64>,
    pub hy: Vec<f64>,
    /// Same layout as the coefficients (shared or per agent).
    pub coef: Vec<f64>,
}

/// What agent i's pass leaves for the others: the contribution of each of its pairs to the
/// neighbour's position and heading gradients.
#[derive(Clone, Copy, Default)]
struct ToNeighbour {
    x: f64,
    y: f64,
    hx: f64,
    hy: f64,
}

/// Agent i's own input gradients and its coefficient gradients.
#[derive(Clone, Copy, Default)]
struct OwnGrads {
    x: f64,
    y: f64,
    hx: f64,
    hy: f64,
    coef: [f64; N_COEF],
}

/// Chain rule of one pair from the upstream `g_c` on its pair weight(s) and `g_d` on its offset
/// (direct terms), through `d²` and φ. Returns the gradient on the offset `(dx, dy)` and adds the
/// heading gradient of agent i and the coefficient gradients.
#[inline]
fn pair_backward(
    p: &Pair,
    forces: &[(usize, f64, f64, f64)],
    c: &[f64],
    hi: P2,
    own: &mut OwnGrads,
) -> (f64, f64) {
    // forces: (g, upstream on c_g, e_g, c_g)
    let phi2 = p.phi * p.phi;
    let (mut gd2, mut gphi2) = (0.0, 0.0);
    for &(g, up, e, cg) in forces {
        own.coef[g] += up * e;
        own.coef[4 + g] += up * cg * p.d2;
        own.coef[8 + g] += up * cg * phi2;
        gd2 += up * cg * c[4 + g];
        gphi2 += up * cg * c[8 + g];
    }
    // φ = σ·atan2(a, b) + offset; ∂atan2/∂a = b / r², ∂atan2/∂b = −a / r².
    let r2 = p.a * p.a + p.b * p.b;
    let (gdot, gcross) = if r2 > 0.0 {
        let gat = p.behind * 2.0 * p.phi * gphi2;
        (p.behind * (-gat * p.a / r2), p.side * (gat * p.b / r2))
    } else {
        (0.0, 0.0)
    };
    // dot = h·u, cross = h × u.
    own.hx += gdot * p.dx + gcross * p.dy;
    own.hy += gdot * p.dy - gcross * p.dx;
    (
        2.0 * p.dx * gd2 + gdot * hi[0] - gcross * hi[1],
        2.0 * p.dy * gd2 + gdot * hi[1] + gcross * hi[0],
    )
}

/// One agent's pair terms from the forward pass, when it kept them.
type Kept<'a> = Option<(&'a [[f64; 4]], &'a [[f64; 2]])>;

/// `e_F` from the kept term, or by eq. 4.
#[inline]
fn weight_at(c: &[f64], g: usize, d2: f64, phi2: f64, kept: Option<f64>) -> (f64, f64) {
    match kept {
        Some(e) => (e, c[g] * e),
        None => weight(c, g, d2, phi2),
    }
}

fn agent_backward(
    i: usize,
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    up: P2,
    to_nb: &mut [ToNeighbour],
    kept: Kept<'_>,
) -> OwnGrads {
    let c = coef.of(i);
    let (xi, yi) = (s.x[i], s.y[i]);
    let hi = [s.hx[i], s.hy[i]];
    let mut own = OwnGrads::default();
    let first = lists.nb_start[i] as usize;
    for (k, e) in lists.neighbours(i).enumerate() {
        let j = lists.nb[e] as usize;
        let t = kept.map(|(nb, _)| nb[k]);
        let (dx, dy) = (s.x[j] - xi, s.y[j] - yi);
        let p = pair_at(dx, dy, hi[0], hi[1], lists.nb_branch[e], t.map(|t| t[0]));
        let phi2 = p.phi * p.phi;
        let (e0, c0) = weight_at(c, 0, p.d2, phi2, t.map(|t| t[1]));
        let (e1, c1) = weight_at(c, 1, p.d2, phi2, t.map(|t| t[2]));
        let (e2, c2) = weight_at(c, 2, p.d2, phi2, t.map(|t| t[3]));
        // F_i += (c_C − c_V)·u + c_A·d_j.
        let gu = up[0] * p.dx + up[1] * p.dy;
        let ga = up[0] * s.hx[j] + up[1] * s.hy[j];
        let (gdx, gdy) = pair_backward(
            &p,
            &[(0, gu, e0, c0), (1, -gu, e1, c1), (2, ga, e2, c2)],
            c,
            hi,
            &mut own,
        );
        let (gdx, gdy) = (gdx + (c0 - c1) * up[0], gdy + (c0 - c1) * up[1]);
        own.x -= gdx;
        own.y -= gdy;
        to_nb[e - first] = ToNeighbour {
            x: gdx,
            y: gdy,
            hx: c2 * up[0],
            hy: c2 * up[1],
        };
    }
    for (k, e) in lists.obstacles(i).enumerate() {
        let q = lists.ob_point[e];
        let t = kept.map(|(_, ob)| ob[k]);
        let p = pair_at(
            q[0] - xi,
            q[1] - yi,
            hi[0],
            hi[1],
            lists.ob_branch[e],
            t.map(|t| t[0]),
        );
        let (e3, c3) = weight_at(c, 3, p.d2, p.phi * p.phi, t.map(|t| t[1]));
        // F_i −= c_O·(q − p_i).
        let go = -(up[0] * p.dx + up[1] * p.dy);
        let (gdx, gdy) = pair_backward(&p, &[(3, go, e3, c3)], c, hi, &mut own);
        own.x -= gdx - c3 * up[0];
        own.y -= gdy - c3 * up[1];
    }
    own
}

/// Backward pass: given `grad_out` (∂L/∂F, laid out like the output of [`forces_forward`]),
/// the gradients of L with respect to positions, headings and coefficients. With `kept` (from
/// [`forces_forward_keep`] on the same inputs) the pair terms are read instead of recomputed.
pub fn forces_backward(
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    grad_out: &[f64],
    kept: Option<&PairTerms>,
) -> ForceGrads {
    let n = lists.n;
    assert_eq!(
        grad_out.len(),
        2 * n,
        "forces_backward: grad_out must hold 2·n values"
    );
    if let Some(t) = kept {
        assert!(
            t.nb.len() == lists.pairs() && t.ob.len() == lists.ob_point.len(),
            "forces_backward: kept terms of other lists"
        );
    }
    let mut to_nb = vec![ToNeighbour::default(); lists.pairs()];
    // Split the per-pair buffer at agent boundaries so each agent writes its own slice.
    let slices = per_agent(to_nb.as_mut_slice(), &lists.nb_start);
    let own: Vec<OwnGrads> = slices
        .into_par_iter()
        .with_min_len(MIN_AGENTS_PER_TASK)
        .enumerate()
        .map(|(i, buf)| {
            let up = [grad_out[2 * i], grad_out[2 * i + 1]];
            let mine = kept.map(|t| (&t.nb[lists.neighbours(i)], &t.ob[lists.obstacles(i)]));
            if up == [0.0, 0.0] {
                OwnGrads::default()
            } else {
                agent_backward(i, lists, s, coef, up, buf, mine)
            }
        })
        .collect();
    let mut g = ForceGrads {
        x: own.iter().map(|o| o.x).collect(),
        y: own.iter().map(|o| o.y).collect(),
        hx: own.iter().map(|o| o.hx).collect(),
        hy: own.iter().map(|o| o.hy).collect(),
        coef: vec![0.0; coef.0.len()],
    };
    // Scatter to neighbours in pair order (deterministic).
    for (e, t) in to_nb.iter().enumerate() {
        let j = lists.nb[e] as usize;
        g.x[j] += t.x;
        g.y[j] += t.y;
        g.hx[j] += t.hx;
        g.hy[j] += t.hy;
    }
    for (i, o) in own.iter().enumerate() {
        let dst = if coef.per_agent() {
            &mut g.coef[i * N_COEF..(i + 1) * N_COEF]
        } else {
            &mut g.coef[..]
        };
        for (d, v) in dst.iter_mut().zip(&o.coef) {
            *d += v;
        }
    }
    g
}

#[cfg(test)]
mod tests;
