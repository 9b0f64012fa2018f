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
//! form: one pass per agent and no intermediate `[N, K]` arrays, and a backward pass that
//! recomputes the pair terms from the inputs instead of storing them.
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
        phi: libm::atan2(a, b) * behind + offset,
    }
}

#[inline]
fn weight(c: &[f64], g: usize, d2: f64, phi2: f64) -> (f64, f64) {
    let e = libm::exp(c[4 + g] * d2 + c[8 + g] * phi2);
    (e, c[g] * e)
}

/// The force on agent `i` (eq. 3), in list order.
#[inline]
fn force_on(i: usize, lists: &PairLists, s: AgentsRef<'_>, coef: Coefficients<'_>) -> P2 {
    let c = coef.of(i);
    let (xi, yi, hxi, hyi) = (s.x[i], s.y[i], s.hx[i], s.hy[i]);
    let (mut fx, mut fy) = (0.0, 0.0);
    for e in lists.neighbours(i) {
        let j = lists.nb[e] as usize;
        let p = pair(s.x[j] - xi, s.y[j] - yi, hxi, hyi, lists.nb_branch[e]);
        let phi2 = p.phi * p.phi;
        let cp = weight(c, 0, p.d2, phi2).1 - weight(c, 1, p.d2, phi2).1;
        let ca = weight(c, 2, p.d2, phi2).1;
        fx += cp * p.dx + ca * s.hx[j];
        fy += cp * p.dy + ca * s.hy[j];
    }
    for e in lists.obstacles(i) {
        let q = lists.ob_point[e];
        let p = pair(q[0] - xi, q[1] - yi, hxi, hyi, lists.ob_branch[e]);
        let co = weight(c, 3, p.d2, p.phi * p.phi).1;
        fx -= co * p.dx;
        fy -= co * p.dy;
    }
    [fx, fy]
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
            let v = force_on(i, lists, s, coef);
            f[0] = v[0];
            f[1] = v[1];
        });
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

fn agent_backward(
    i: usize,
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    up: P2,
    to_nb: &mut [ToNeighbour],
) -> OwnGrads {
    let c = coef.of(i);
    let (xi, yi) = (s.x[i], s.y[i]);
    let hi = [s.hx[i], s.hy[i]];
    let mut own = OwnGrads::default();
    let first = lists.nb_start[i] as usize;
    for e in lists.neighbours(i) {
        let j = lists.nb[e] as usize;
        let p = pair(s.x[j] - xi, s.y[j] - yi, hi[0], hi[1], lists.nb_branch[e]);
        let phi2 = p.phi * p.phi;
        let (e0, c0) = weight(c, 0, p.d2, phi2);
        let (e1, c1) = weight(c, 1, p.d2, phi2);
        let (e2, c2) = weight(c, 2, p.d2, phi2);
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
    for e in lists.obstacles(i) {
        let q = lists.ob_point[e];
        let p = pair(q[0] - xi, q[1] - yi, hi[0], hi[1], lists.ob_branch[e]);
        let (e3, c3) = weight(c, 3, p.d2, p.phi * p.phi);
        // F_i −= c_O·(q − p_i).
        let go = -(up[0] * p.dx + up[1] * p.dy);
        let (gdx, gdy) = pair_backward(&p, &[(3, go, e3, c3)], c, hi, &mut own);
        own.x -= gdx - c3 * up[0];
        own.y -= gdy - c3 * up[1];
    }
    own
}

/// Backward pass: given `grad_out` (∂L/∂F, laid out like the output of [`forces_forward`]),
/// the gradients of L with respect to positions, headings and coefficients.
pub fn forces_backward(
    lists: &PairLists,
    s: AgentsRef<'_>,
    coef: Coefficients<'_>,
    grad_out: &[f64],
) -> ForceGrads {
    let n = lists.n;
    assert_eq!(
        grad_out.len(),
        2 * n,
        "forces_backward: grad_out must hold 2·n values"
    );
    let mut to_nb = vec![ToNeighbour::default(); lists.pairs()];
    // Split the per-pair buffer at agent boundaries so each agent writes its own slice.
    let mut slices: Vec<&mut [ToNeighbour]> = Vec::with_capacity(n);
    let mut rest = to_nb.as_mut_slice();
    for i in 0..n {
        let (head, tail) = rest.split_at_mut(lists.neighbours(i).len());
        slices.push(head);
        rest = tail;
    }
    let own: Vec<OwnGrads> = slices
        .into_par_iter()
        .with_min_len(MIN_AGENTS_PER_TASK)
        .enumerate()
        .map(|(i, buf)| {
            let up = [grad_out[2 * i], grad_out[2 * i + 1]];
            if up == [0.0, 0.0] {
                OwnGrads::default()
            } else {
                agent_backward(i, lists, s, coef, up, buf)
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
mod tests {
    use super::*;
    use crate::perception::{perceive, PerceptionConfig};
    use crate::{Capsule, ObstacleMap};
    use rand::{Rng, SeedableRng};

    fn scene(seed: u64, n: usize) -> (Vec<P2>, Vec<P2>, ObstacleMap) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let side = (2.0 * n as f64).sqrt();
        let pos: Vec<P2> = (0..n)
            .map(|_| [rng.gen_range(0.0..side), rng.gen_range(0.0..side)])
            .collect();
        let head: Vec<P2> = (0..n)
            .map(|_| {
                let a: f64 = rng.gen_range(-3.2..3.2);
                [a.cos(), a.sin()]
            })
            .collect();
        let mut map = ObstacleMap::empty([0.0, 0.0], 1.5, 14, 14);
        for _ in 0..12 {
            let c = rng.gen_range(0..map.blocked.len());
            map.blocked[c] = true;
        }
        (pos, head, map)
    }

    fn setup(seed: u64, n: usize) -> (PairLists, [Vec<f64>; 4], Vec<f64>) {
        let (pos, head, map) = scene(seed, n);
        let cfg = PerceptionConfig {
            radius: 4.0,
            capsule: Capsule {
                half_length: 0.3,
                radius: 0.2,
            },
            occlusion: true,
            max_neighbours: 12,
            max_obstacles: 8,
            front_cone: 1.0,
        };
        let p = perceive(&pos, &head, Some(&map), &cfg);
        let lists = PairLists::from_perception(&p);
        let s = [
            pos.iter().map(|p| p[0]).collect(),
            pos.iter().map(|p| p[1]).collect(),
            head.iter().map(|h| h[0]).collect(),
            head.iter().map(|h| h[1]).collect(),
        ];
        let mut coef = vec![0.0; N_COEF];
        for g in 0..4 {
            coef[g] = 1.0 + 0.7 * g as f64;
            coef[4 + g] = -0.5 / (1.5 + 0.4 * g as f64).powi(2);
            coef[8 + g] = -0.5 / (1.2 + 0.5 * g as f64).powi(2);
        }
        (lists, s, coef)
    }

    fn loss(lists: &PairLists, s: &[Vec<f64>; 4], coef: &[f64], w: &[f64]) -> f64 {
        let mut out = vec![0.0; 2 * lists.n];
        let a = AgentsRef {
            x: &s[0],
            y: &s[1],
            hx: &s[2],
            hy: &s[3],
        };
        forces_forward(lists, a, Coefficients(coef), &mut out);
        out.iter().zip(w).map(|(f, w)| f * w).sum()
    }

    /// Every gradient of `L = Σ w·F` against 4-point central differences of the forward pass.
    #[test]
    fn backward_matches_central_differences() {
        let (lists, s, coef) = setup(3, 120);
        assert!(lists.pairs() > 200 && !lists.ob_point.is_empty());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let w: Vec<f64> = (0..2 * lists.n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        let a = AgentsRef {
            x: &s[0],
            y: &s[1],
            hx: &s[2],
            hy: &s[3],
        };
        let g = forces_backward(&lists, a, Coefficients(&coef), &w);
        let h = 1e-5;
        let fd = |f: &dyn Fn(f64) -> f64| {
            (8.0 * (f(h) - f(-h)) - (f(2.0 * h) - f(-2.0 * h))) / (12.0 * h)
        };
        let mut worst = 0.0f64;
        let mut check = |got: f64, want: f64| {
            worst = worst.max((got - want).abs() / want.abs().max(1.0));
        };
        for c in 0..N_COEF {
            let want = fd(&|d| {
                let mut k = coef.clone();
                k[c] += d;
                loss(&lists, &s, &k, &w)
            });
            check(g.coef[c], want);
        }
        let grads = [&g.x, &g.y, &g.hx, &g.hy];
        for (v, gv) in grads.iter().enumerate() {
            for i in (0..lists.n).step_by(7) {
                let want = fd(&|d| {
                    let mut t = s.clone();
                    t[v][i] += d;
                    loss(&lists, &t, &coef, &w)
                });
                check(gv[i], want);
            }
        }
        assert!(worst < 1e-7, "worst relative error {worst:e}");
    }

    #[test]
    fn per_agent_coefficients_equal_shared_ones() {
        let (lists, s, coef) = setup(4, 200);
        let per: Vec<f64> = (0..lists.n).flat_map(|_| coef.clone()).collect();
        let a = AgentsRef {
            x: &s[0],
            y: &s[1],
            hx: &s[2],
            hy: &s[3],
        };
        let (mut f1, mut f2) = (vec![0.0; 2 * lists.n], vec![0.0; 2 * lists.n]);
        forces_forward(&lists, a, Coefficients(&coef), &mut f1);
        forces_forward(&lists, a, Coefficients(&per), &mut f2);
        assert_eq!(f1, f2);
        let w = vec![0.5; 2 * lists.n];
        let g1 = forces_backward(&lists, a, Coefficients(&coef), &w);
        let g2 = forces_backward(&lists, a, Coefficients(&per), &w);
        assert_eq!(g1.x, g2.x);
        assert_eq!(g1.hy, g2.hy);
        for c in 0..N_COEF {
            let sum: f64 = (0..lists.n).map(|i| g2.coef[i * N_COEF + c]).sum();
            assert!((sum - g1.coef[c]).abs() <= 1e-9 * (1.0 + g1.coef[c].abs()));
        }
    }

    #[test]
    fn thread_count_does_not_change_forces_or_gradients() {
        let (lists, s, coef) = setup(5, 3000);
        let a = AgentsRef {
            x: &s[0],
            y: &s[1],
            hx: &s[2],
            hy: &s[3],
        };
        let w: Vec<f64> = (0..2 * lists.n).map(|i| (i as f64 * 0.37).sin()).collect();
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| {
                    let mut f = vec![0.0; 2 * lists.n];
                    forces_forward(&lists, a, Coefficients(&coef), &mut f);
                    (f, forces_backward(&lists, a, Coefficients(&coef), &w))
                })
        };
        assert_eq!(run(1), run(3));
    }

    #[test]
    fn compact_lists_keep_exactly_the_unmasked_entries() {
        let (pos, head, map) = scene(6, 150);
        let cfg = PerceptionConfig {
            radius: 4.0,
            capsule: Capsule {
                half_length: 0.3,
                radius: 0.2,
            },
            occlusion: true,
            max_neighbours: 32,
            max_obstacles: 16,
            front_cone: 1.0,
        };
        let p = perceive(&pos, &head, Some(&map), &cfg);
        let l = PairLists::from_perception(&p);
        let real: usize = p.neighbour_mask.iter().map(|&m| m as usize).sum();
        assert_eq!(l.pairs(), real);
        assert!(p.k > 1 && real < p.n * p.k, "the scene must have padding");
        for i in 0..p.n {
            let want: Vec<u32> = (0..p.k)
                .filter(|&s| p.neighbour_mask[i * p.k + s] == 1)
                .map(|s| p.neighbours[i * p.k + s])
                .collect();
            assert_eq!(&l.nb[l.neighbours(i)], &want[..]);
        }
    }
}
