//! The whole-sequence lifting energy (Lin 2019, the future work of §5, built on eq. 3.1–3.4 and
//! Algorithm 1's d_sep; herdfit's `lift::sequence` documents each term) and its gradient with
//! respect to every log-depth, hand-derived, as plain Rust over flat `f64` slices.
//!
//! With log-depths u_i, depths d_i = e^{u_i}, points q_i = d_i r_i (eq. 1.1 without the camera
//! centre, which cancels in every difference), velocities v_k = q_c − q_p (eq. 3.3), speeds
//! s_k = √(‖v_k‖² + ε v_t²) and headings h_k = v_k / s_k, the energy is
//! `E = scale · Σ_t w_t E_t` with
//! - speed: Σ_k (s_k / v_t − 1)²
//! - level: Σ_k h_{k,z}²
//! - accel: Σ_{(a,b)} ‖v_b − v_a‖² / v_t²
//! - align: Σ_{(a,b)} ‖h_b − h_a‖²
//! - cohesion: Σ_{(i,j)} (u_j − u_i)²
//! - separation: Σ_{(i,j)} max(0, 1 − √(‖q_j − q_i‖² + ε d_sep²) / d_sep)²
//!
//! (ε = 1e-12). The backward pass is the chain rule written out: ∂E/∂h → ∂E/∂v through
//! ∂h/∂v = (I − h hᵀ)/s, ∂E/∂v → ∂E/∂q by the velocity differences, and
//! ∂E/∂u_i = d_i (∂E/∂q_i · r_i) + ∂E_cohesion/∂u_i. herdfit keeps the burn-autodiff form of the
//! same energy as the reference it is tested against (`tests/lift_gradient.rs`).
//!
//! Parallel (rayon) and deterministic: the lists are cut into fixed blocks of 8192 targets
//! ([`SeqPlan`]); element-wise passes run block by block, scatters run even blocks then odd ones
//! (each block writes only its own range and the one before, so blocks of one parity never touch
//! the same entry), and partial sums are added in block order — the same bytes for any thread
//! count.

use rayon::prelude::*;

/// The index lists of the energy (see herdfit's `lift::sequence::Structure`).
#[derive(Clone, Copy, Debug)]
pub struct SeqStructure<'a> {
    /// Viewing ray of each observation, scaled to unit depth.
    pub ray: &'a [[f64; 3]],
    /// Velocities: (observation at f − 1, observation at f).
    pub vel: &'a [(usize, usize)],
    /// Accelerations: consecutive velocities (indices into `vel`).
    pub acc: &'a [(usize, usize)],
    /// Same-frame neighbour pairs of observations.
    pub pairs: &'a [(usize, usize)],
    /// Neighbour pairs of velocities (indices into `vel`).
    pub align: &'a [(usize, usize)],
}

/// Weights of the six terms, the common factor and the two lengths.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SeqWeights {
    pub accel: f64,
    pub speed: f64,
    pub align: f64,
    pub cohesion: f64,
    pub separation: f64,
    pub level: f64,
    /// Multiplies every term (herdfit: 1 / observations).
    pub scale: f64,
    pub v_target: f64,
    pub d_sep: f64,
}

/// The six weighted terms at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SeqTerms {
    pub accel: f64,
    pub speed: f64,
    pub align: f64,
    pub cohesion: f64,
    pub separation: f64,
    pub level: f64,
}

impl SeqTerms {
    /// Their sum.
    pub fn total(&self) -> f64 {
        self.accel + self.speed + self.align + self.cohesion + self.separation + self.level
    }
}

/// Per-velocity state of one evaluation.
#[derive(Clone, Copy, Debug, Default)]
struct Vel {
    v: [f64; 3],
    /// 1 / s (the heading h = v / s is recomputed where needed: a smaller record to stream).
    inv_s: f64,
    /// ∂E/∂v and ∂E/∂h so far.
    gv: [f64; 3],
    gh: [f64; 3],
}

/// Elements per block of the parallel passes (fixed, so results do not depend on the thread
/// count).
const BLOCK: usize = 8192;

impl Vel {
    /// The heading h = v / s.
    #[inline]
    fn h(&self) -> [f64; 3] {
        scaled(self.inv_s, self.v)
    }
}

/// A scatter list cut into blocks of its target space. Each entry belongs to the block of its
/// larger target (`forward` false: it writes only into `starts[b − 1]..starts[b + 1]`) or of its
/// smaller one (`forward`: `starts[b]..starts[b + 2]`), so blocks of one parity write disjoint
/// ranges and run in parallel (even blocks, then odd ones).
#[derive(Clone, Debug, Default)]
struct Blocks {
    /// Block starts in the target space, and its length last.
    starts: Vec<usize>,
    /// Entries of each block.
    ranges: Vec<std::ops::Range<usize>>,
    forward: bool,
}

impl Blocks {
    /// Blocks of `len` targets for entries touching targets (smaller, larger) = `touch(e)`: by
    /// the larger target if the entries are in its block order and reach back at most one block,
    /// else by the smaller one likewise, else one block (a sequential pass).
    fn new<E>(
        entries: &[E],
        len: usize,
        block: usize,
        touch: impl Fn(&E) -> (usize, usize),
    ) -> Blocks {
        let nb = len.div_ceil(block).max(1);
        let mut starts: Vec<usize> = (0..nb).map(|b| b * block).collect();
        starts.push(len);
        let try_by = |forward: bool| -> Option<Vec<std::ops::Range<usize>>> {
            let mut ranges = vec![0..0; nb];
            let mut last = 0;
            for (k, e) in entries.iter().enumerate() {
                let (lo, hi) = touch(e);
                let owner = if forward { lo } else { hi } / block;
                let (from, to) = if forward {
                    (starts[owner], starts[(owner + 2).min(nb)])
                } else {
                    (starts[owner.saturating_sub(1)], starts[owner + 1])
                };
                if owner < last || owner >= nb || lo < from || hi >= to {
                    return None;
                }
                if ranges[owner].is_empty() {
                    ranges[owner] = k..k;
                }
                ranges[owner].end = k + 1;
                last = owner;
            }
            Some(ranges)
        };
        if nb > 1 {
            for forward in [false, true] {
                if let Some(ranges) = try_by(forward) {
                    return Blocks {
                        starts,
                        ranges,
                        forward,
                    };
                }
            }
        }
        Blocks {
            starts: vec![0, len],
            ranges: std::iter::once(0..entries.len()).collect(),
            forward: false,
        }
    }

    /// Runs `f(targets, offset, first, entries)` on every block — even blocks in parallel, then
    /// odd ones — where `targets[k − offset]` is target k and `entries` starts at entry `first`;
    /// returns the blocks' partial sums added in block order.
    fn run<T: Send, E: Sync>(
        &self,
        targets: &mut [T],
        entries: &[E],
        f: impl Fn(&mut [T], usize, usize, &[E]) -> [f64; 2] + Sync,
    ) -> [f64; 2] {
        let nb = self.ranges.len();
        let mut part = vec![[0.0; 2]; nb];
        for parity in 0..2 {
            let mut tasks = Vec::new();
            let mut rest = &mut targets[..];
            let mut consumed = 0;
            for b in (parity..nb).step_by(2) {
                let (lo, hi) = if self.forward {
                    (self.starts[b], self.starts[(b + 2).min(nb)])
                } else {
                    (self.starts[b.saturating_sub(1)], self.starts[b + 1])
                };
                let tail = std::mem::take(&mut rest);
                let (_, tail) = tail.split_at_mut(lo - consumed);
                let (mine, tail) = tail.split_at_mut(hi - lo);
                rest = tail;
                consumed = hi;
                tasks.push((b, lo, mine));
            }
            let one = |(b, lo, mine): (usize, usize, &mut [T])| {
                let r = self.ranges[b].clone();
                (b, f(mine, lo, r.start, &entries[r]))
            };
            // One task runs here: handing it to the pool would only add a wake-up.
            let sums: Vec<(usize, [f64; 2])> = if tasks.len() == 1 {
                tasks.into_iter().map(one).collect()
            } else {
                tasks.into_par_iter().map(one).collect()
            };
            for (b, s) in sums {
                part[b] = s;
            }
        }
        part.iter()
            .fold([0.0; 2], |a, s| [a[0] + s[0], a[1] + s[1]])
    }
}

/// The blocks of one problem's lists, built once ([`SeqPlan::new`]) and reused by every
/// evaluation.
#[derive(Clone, Debug, Default)]
pub struct SeqPlan {
    /// Elements per block.
    block: usize,
    n: usize,
    nv: usize,
    /// Velocities into ∂E/∂q (observation space).
    vel: Blocks,
    /// Accelerations into ∂E/∂v and alignment pairs into ∂E/∂h (velocity space).
    acc: Blocks,
    align: Blocks,
    /// Same-frame pairs into ∂E/∂q and ∂E/∂u (observation space).
    pairs: Blocks,
}

impl SeqPlan {
    /// The plan of `st`'s lists (sorted by their larger index, as herdfit builds them, they run in
    /// parallel blocks; otherwise sequentially, with the same result).
    pub fn new(st: &SeqStructure) -> SeqPlan {
        SeqPlan::with_block(st, BLOCK)
    }

    /// The plan with `block` elements per block (tests cut small problems into many blocks).
    pub fn with_block(st: &SeqStructure, block: usize) -> SeqPlan {
        let block = block.max(1);
        let (n, nv) = (st.ray.len(), st.vel.len());
        let ordered = |&(a, b): &(usize, usize)| (a.min(b), a.max(b));
        SeqPlan {
            block,
            n,
            nv,
            vel: Blocks::new(st.vel, n, block, ordered),
            acc: Blocks::new(st.acc, nv, block, ordered),
            align: Blocks::new(st.align, nv, block, ordered),
            pairs: Blocks::new(st.pairs, n, block, ordered),
        }
    }

    /// Blocks of the four lists (1 where a list runs sequentially).
    pub fn blocks(&self) -> [usize; 4] {
        [&self.vel, &self.acc, &self.align, &self.pairs].map(|b| b.ranges.len())
    }
}

/// Buffers reused across evaluations (one allocation per problem, not per evaluation).
#[derive(Clone, Debug, Default)]
pub struct SeqWorkspace {
    /// q_i and, last, d_i.
    dq: Vec<[f64; 4]>,
    vel: Vec<Vel>,
    /// ∂E/∂q and, last, the direct ∂E/∂u of cohesion.
    gq: Vec<[f64; 4]>,
}

const EPS: f64 = 1e-12;

#[inline]
fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// q_j − q_i of two `[q, d]` entries.
#[inline]
fn sub4(a: [f64; 4], b: [f64; 4]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
fn norm2(a: [f64; 3]) -> f64 {
    a[0] * a[0] + a[1] * a[1] + a[2] * a[2]
}

#[inline]
fn axpy(y: &mut [f64; 3], k: f64, x: [f64; 3]) {
    y[0] += k * x[0];
    y[1] += k * x[1];
    y[2] += k * x[2];
}

#[inline]
fn axpy4(y: &mut [f64; 4], k: f64, x: [f64; 3]) {
    y[0] += k * x[0];
    y[1] += k * x[1];
    y[2] += k * x[2];
}

#[inline]
fn scaled(k: f64, a: [f64; 3]) -> [f64; 3] {
    [k * a[0], k * a[1], k * a[2]]
}

/// Sums of fixed-size chunks of a parallel map, added in chunk order.
fn chunk_sums<T: Send>(
    data: &mut [T],
    block: usize,
    f: impl Fn(usize, &mut [T]) -> [f64; 2] + Sync,
) -> [f64; 2] {
    if data.len() <= block {
        return f(0, data);
    }
    let sums: Vec<[f64; 2]> = data
        .par_chunks_mut(block)
        .enumerate()
        .map(|(c, chunk)| f(c * block, chunk))
        .collect();
    sums.iter()
        .fold([0.0; 2], |a, s| [a[0] + s[0], a[1] + s[1]])
}

/// The energy's terms at log-depths `u` and, when `grad` is given, ∂E/∂u written into it (one
/// entry per observation; overwritten, not accumulated). `plan` is [`SeqPlan::new`] of `st`.
pub fn sequence_energy(
    st: &SeqStructure,
    plan: &SeqPlan,
    w: &SeqWeights,
    u: &[f64],
    grad: Option<&mut [f64]>,
    ws: &mut SeqWorkspace,
) -> SeqTerms {
    let (n, nv) = (u.len(), st.vel.len());
    assert_eq!(st.ray.len(), n, "one ray per log-depth");
    assert!(
        plan.n == n && plan.nv == nv,
        "the plan of another structure"
    );
    ws.dq.resize(n, [0.0; 4]);
    ws.vel.resize(nv, Vel::default());
    let SeqWorkspace { dq, vel, gq } = ws;
    let block = plan.block;
    chunk_sums(dq, block, |at, chunk| {
        for (k, x) in chunk.iter_mut().enumerate() {
            let (d, r) = (u[at + k].exp(), st.ray[at + k]);
            *x = [d * r[0], d * r[1], d * r[2], d];
        }
        [0.0; 2]
    });
    let q = &dq[..];
    let mut t = SeqTerms::default();
    let vt = w.v_target;
    // Velocities, speeds, headings and the per-velocity terms (speed, level).
    let (c_speed, c_level) = (w.speed * w.scale, w.level * w.scale);
    let [speed, level] = chunk_sums(vel, block, |at, chunk| {
        let mut sum = [0.0; 2];
        for (k, x) in chunk.iter_mut().enumerate() {
            let (p, c) = st.vel[at + k];
            let v = sub4(q[c], q[p]);
            let s = (norm2(v) + EPS * vt * vt).sqrt();
            let inv_s = 1.0 / s;
            let r = s / vt - 1.0;
            let h = scaled(inv_s, v);
            sum[0] += r * r;
            sum[1] += h[2] * h[2];
            // ∂(c r²)/∂v = 2c r / v_t · v / s = 2c r / v_t · h; ∂(c h_z²)/∂h = (0, 0, 2c h_z).
            *x = Vel {
                v,
                inv_s,
                gv: scaled(2.0 * c_speed * r / vt, h),
                gh: [0.0, 0.0, 2.0 * c_level * h[2]],
            };
        }
        sum
    });
    t.speed = c_speed * speed;
    t.level = c_level * level;
    // Accelerations.
    let c_acc = w.accel * w.scale / (vt * vt);
    t.accel = c_acc
        * plan.acc.run(vel, st.acc, |x, off, _, list| {
            let mut sum = 0.0;
            for &(a, b) in list {
                let dv = sub(x[b - off].v, x[a - off].v);
                sum += norm2(dv);
                let g = scaled(2.0 * c_acc, dv);
                axpy(&mut x[b - off].gv, 1.0, g);
                axpy(&mut x[a - off].gv, -1.0, g);
            }
            [sum, 0.0]
        })[0];
    // Alignment of neighbours' headings.
    let c_align = w.align * w.scale;
    t.align = c_align
        * plan.align.run(vel, st.align, |x, off, _, list| {
            let mut sum = 0.0;
            for &(a, b) in list {
                let dh = sub(x[b - off].h(), x[a - off].h());
                sum += norm2(dh);
                let g = scaled(2.0 * c_align, dh);
                axpy(&mut x[b - off].gh, 1.0, g);
                axpy(&mut x[a - off].gh, -1.0, g);
            }
            [sum, 0.0]
        })[0];
    let Some(gu) = grad else {
        let [coh, sep] = pair_values(st, plan, w, u, q);
        t.cohesion = w.cohesion * w.scale * coh;
        t.separation = w.separation * w.scale * sep;
        return t;
    };
    assert_eq!(gu.len(), n, "one gradient entry per log-depth");
    gq.clear();
    gq.resize(n, [0.0; 4]);
    // ∂E/∂v += (I − h hᵀ)/s · ∂E/∂h, then ∂E/∂q through v = q_c − q_p.
    let vel = &vel[..];
    plan.vel.run(gq, st.vel, |g, off, first, list| {
        for (k, &(p, c)) in list.iter().enumerate() {
            let x = &vel[first + k];
            let (h, gh) = (x.h(), x.gh);
            let hg = h[0] * gh[0] + h[1] * gh[1] + h[2] * gh[2];
            let mut gk = x.gv;
            axpy(
                &mut gk,
                x.inv_s,
                [gh[0] - hg * h[0], gh[1] - hg * h[1], gh[2] - hg * h[2]],
            );
            axpy4(&mut g[c - off], 1.0, gk);
            axpy4(&mut g[p - off], -1.0, gk);
        }
        [0.0; 2]
    });
    let (c_coh, c_sep, ds) = (w.cohesion * w.scale, w.separation * w.scale, w.d_sep);
    let near = ds * ds;
    let [coh, sep] = plan.pairs.run(gq, st.pairs, |g, off, _, list| {
        let mut sum = [0.0; 2];
        for &(i, j) in list {
            let du = u[j] - u[i];
            sum[0] += du * du;
            g[j - off][3] += 2.0 * c_coh * du;
            g[i - off][3] -= 2.0 * c_coh * du;
            let dq = sub4(q[j], q[i]);
            // hinge > 0 ⇔ ‖dq‖² + ε d_sep² < d_sep²: the square root only inside d_sep.
            let d2 = norm2(dq) + EPS * near;
            if d2 < near {
                let dist = d2.sqrt();
                let hinge = 1.0 - dist / ds;
                sum[1] += hinge * hinge;
                // ∂(c hinge²)/∂q_j = −2c hinge / d_sep · dq / dist.
                let gj = scaled(-2.0 * c_sep * hinge / (ds * dist), dq);
                axpy4(&mut g[j - off], 1.0, gj);
                axpy4(&mut g[i - off], -1.0, gj);
            }
        }
        sum
    });
    t.cohesion = c_coh * coh;
    t.separation = c_sep * sep;
    let gq = &gq[..];
    chunk_sums(gu, block, |at, chunk| {
        for (k, g) in chunk.iter_mut().enumerate() {
            let (gi, r, d) = (gq[at + k], st.ray[at + k], q[at + k][3]);
            *g = gi[3] + d * (gi[0] * r[0] + gi[1] * r[1] + gi[2] * r[2]);
        }
        [0.0; 2]
    });
    t
}

/// The sums of cohesion and separation (unweighted) over the pairs, without gradients.
fn pair_values(
    st: &SeqStructure,
    plan: &SeqPlan,
    w: &SeqWeights,
    u: &[f64],
    q: &[[f64; 4]],
) -> [f64; 2] {
    let ds = w.d_sep;
    let near = ds * ds;
    let sum_of = |r: &std::ops::Range<usize>| {
        let mut sum = [0.0; 2];
        for &(i, j) in &st.pairs[r.clone()] {
            sum[0] += (u[j] - u[i]).powi(2);
            let d2 = norm2(sub4(q[j], q[i])) + EPS * near;
            if d2 < near {
                sum[1] += (1.0 - d2.sqrt() / ds).powi(2);
            }
        }
        sum
    };
    let ranges = &plan.pairs.ranges;
    let sums: Vec<[f64; 2]> = if ranges.len() == 1 {
        ranges.iter().map(sum_of).collect()
    } else {
        ranges.par_iter().map(sum_of).collect()
    };
    sums.iter()
        .fold([0.0; 2], |a, s| [a[0] + s[0], a[1] + s[1]])
}
