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
//! Cache-tiled, parallel (rayon) and deterministic ([`SeqPlan`]): one sweep over tiles of a few
//! frames does every pass of a tile while its data is in cache, chunks of tiles are swept in
//! parallel, and each entry's gradient contributions are added in list order whatever the cuts —
//! the same bytes for any thread count.

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

impl Vel {
    /// The heading h = v / s.
    #[inline]
    fn h(&self) -> [f64; 3] {
        scaled(self.inv_s, self.v)
    }
}

mod plan;
pub use plan::SeqPlan;

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

/// `[q, d]` of observation i at log-depths u (eq. 1.1 without the camera centre).
#[inline]
fn point(u: &[f64], ray: &[[f64; 3]], i: usize) -> [f64; 4] {
    let (d, r) = (u[i].exp(), ray[i]);
    [d * r[0], d * r[1], d * r[2], d]
}

/// What every chunk's sweep reads.
struct Shared<'a> {
    st: &'a SeqStructure<'a>,
    plan: &'a SeqPlan,
    u: &'a [f64],
    grad: bool,
    vt: f64,
    ds: f64,
    c_speed: f64,
    c_level: f64,
    c_acc: f64,
    c_align: f64,
    c_coh: f64,
    c_sep: f64,
}

/// Gradient contributions handed to the previous chunk: (index, value), in list order.
type Given = Vec<(usize, [f64; 3])>;

/// Partial sums of one chunk: speed, level, accel, align, cohesion, separation (unweighted).
type Sums = [f64; 6];

/// One chunk's slices of the workspace and the gradient, and what it hands over.
struct Chunk<'a> {
    /// Its tiles.
    t0: usize,
    t1: usize,
    /// Its first observation and velocity.
    o0: usize,
    v0: usize,
    dq: &'a mut [[f64; 4]],
    vel: &'a mut [Vel],
    gq: &'a mut [[f64; 4]],
    gu: &'a mut [f64],
    sums: Sums,
    /// Contributions to the previous chunk's ∂E/∂v and ∂E/∂q, in list order.
    give_v: Given,
    give_q: Given,
}

/// Splits `data` at `at` (offsets, the first 0 and the last `data.len()`).
fn split_at<'a, T>(mut data: &'a mut [T], at: &[usize]) -> Vec<&'a mut [T]> {
    let mut out = Vec::with_capacity(at.len().saturating_sub(1));
    for w in at.windows(2) {
        let (head, tail) = std::mem::take(&mut data).split_at_mut(w[1] - w[0]);
        out.push(head);
        data = tail;
    }
    out
}

impl Chunk<'_> {
    /// Positions of tile t; ∂E/∂q zeroed.
    fn points(&mut self, s: &Shared, t: usize) {
        let p = s.plan;
        for i in p.obs[t]..p.obs[t + 1] {
            self.dq[i - self.o0] = point(s.u, s.st.ray, i);
        }
        if s.grad {
            self.gq[p.obs[t] - self.o0..p.obs[t + 1] - self.o0].fill([0.0; 4]);
        }
    }

    /// `[q, d]` of observation i (recomputed when it is the previous chunk's).
    #[inline]
    fn q(&self, s: &Shared, i: usize) -> [f64; 4] {
        if i >= self.o0 {
            self.dq[i - self.o0]
        } else {
            point(s.u, s.st.ray, i)
        }
    }

    /// Velocities of tile t with their speed and level terms.
    fn velocities(&mut self, s: &Shared, t: usize) {
        let p = s.plan;
        let vt = s.vt;
        for k in p.vel[t]..p.vel[t + 1] {
            let (a, c) = s.st.vel[k];
            let v = sub4(self.q(s, c), self.q(s, a));
            let sp = (norm2(v) + EPS * vt * vt).sqrt();
            let inv_s = 1.0 / sp;
            let r = sp / vt - 1.0;
            let h = scaled(inv_s, v);
            self.sums[0] += r * r;
            self.sums[1] += h[2] * h[2];
            // ∂(c r²)/∂v = 2c r / v_t · v / s = 2c r / v_t · h; ∂(c h_z²)/∂h = (0, 0, 2c h_z).
            self.vel[k - self.v0] = Vel {
                v,
                inv_s,
                gv: scaled(2.0 * s.c_speed * r / vt, h),
                gh: [0.0, 0.0, 2.0 * s.c_level * h[2]],
            };
        }
    }

    /// Accelerations and alignment pairs of tile t.
    fn accelerations(&mut self, s: &Shared, t: usize) {
        let p = s.plan;
        let v0 = self.v0;
        for &(a, b) in &s.st.acc[p.acc[t]..p.acc[t + 1]] {
            let va = if a >= v0 {
                self.vel[a - v0].v
            } else {
                let (i, j) = s.st.vel[a];
                sub4(self.q(s, j), self.q(s, i))
            };
            let dv = sub(self.vel[b - v0].v, va);
            self.sums[2] += norm2(dv);
            let g = scaled(2.0 * s.c_acc, dv);
            axpy(&mut self.vel[b - v0].gv, 1.0, g);
            if a >= v0 {
                axpy(&mut self.vel[a - v0].gv, -1.0, g);
            } else {
                self.give_v.push((a, scaled(-1.0, g)));
            }
        }
        for &(a, b) in &s.st.align[p.align[t]..p.align[t + 1]] {
            let (a, b) = (a - v0, b - v0);
            let dh = sub(self.vel[b].h(), self.vel[a].h());
            self.sums[3] += norm2(dh);
            let g = scaled(2.0 * s.c_align, dh);
            axpy(&mut self.vel[b].gh, 1.0, g);
            axpy(&mut self.vel[a].gh, -1.0, g);
        }
    }

    /// ∂E/∂v += (I − h hᵀ)/s · ∂E/∂h for the velocities of tile t, then ∂E/∂q through
    /// v = q_c − q_p.
    fn velocity_backward(&mut self, s: &Shared, t: usize) {
        let p = s.plan;
        for k in p.vel[t]..p.vel[t + 1] {
            let (a, c) = s.st.vel[k];
            let x = &self.vel[k - self.v0];
            let (h, gh) = (x.h(), x.gh);
            let hg = h[0] * gh[0] + h[1] * gh[1] + h[2] * gh[2];
            let mut gk = x.gv;
            axpy(
                &mut gk,
                x.inv_s,
                [gh[0] - hg * h[0], gh[1] - hg * h[1], gh[2] - hg * h[2]],
            );
            axpy4(&mut self.gq[c - self.o0], 1.0, gk);
            if a >= self.o0 {
                axpy4(&mut self.gq[a - self.o0], -1.0, gk);
            } else {
                self.give_q.push((a, scaled(-1.0, gk)));
            }
        }
    }

    /// Cohesion and separation of tile t's pairs and, with the gradient, ∂E/∂u of its
    /// observations.
    fn pairs(&mut self, s: &Shared, t: usize) {
        let p = s.plan;
        let (ds, o0) = (s.ds, self.o0);
        let near = ds * ds;
        for &(i, j) in &s.st.pairs[p.pairs[t]..p.pairs[t + 1]] {
            let du = s.u[j] - s.u[i];
            self.sums[4] += du * du;
            let dq = sub4(self.dq[j - o0], self.dq[i - o0]);
            if s.grad {
                self.gq[j - o0][3] += 2.0 * s.c_coh * du;
                self.gq[i - o0][3] -= 2.0 * s.c_coh * du;
            }
            // hinge > 0 ⇔ ‖dq‖² + ε d_sep² < d_sep²: the square root only inside d_sep.
            let d2 = norm2(dq) + EPS * near;
            if d2 < near {
                let dist = d2.sqrt();
                let hinge = 1.0 - dist / ds;
                self.sums[5] += hinge * hinge;
                if s.grad {
                    // ∂(c hinge²)/∂q_j = −2c hinge / d_sep · dq / dist.
                    let gj = scaled(-2.0 * s.c_sep * hinge / (ds * dist), dq);
                    axpy4(&mut self.gq[j - o0], 1.0, gj);
                    axpy4(&mut self.gq[i - o0], -1.0, gj);
                }
            }
        }
        if s.grad {
            for i in p.obs[t]..p.obs[t + 1] {
                let (gi, r, d) = (self.gq[i - o0], s.st.ray[i], self.dq[i - o0][3]);
                self.gu[i - o0] = gi[3] + d * (gi[0] * r[0] + gi[1] * r[1] + gi[2] * r[2]);
            }
        }
    }

    /// The sweep up to what needs the next chunk's hand-over: the last tile's velocity backward
    /// and the last two tiles' pairs.
    fn sweep(&mut self, s: &Shared) {
        for t in self.t0..self.t1 {
            self.points(s, t);
            self.velocities(s, t);
            self.accelerations(s, t);
            if t > self.t0 && s.grad {
                self.velocity_backward(s, t - 1);
            }
            if t >= self.t0 + 2 {
                self.pairs(s, t - 2);
            }
        }
    }

    /// The rest of the sweep, with the next chunk's hand-over.
    fn finish(&mut self, s: &Shared, next: Option<&(Given, Given)>) {
        let last = self.t1 - 1;
        if s.grad {
            for &(k, g) in next.map_or(&[][..], |n| &n.0[..]) {
                axpy(&mut self.vel[k - self.v0].gv, 1.0, g);
            }
            self.velocity_backward(s, last);
            for &(i, g) in next.map_or(&[][..], |n| &n.1[..]) {
                axpy4(&mut self.gq[i - self.o0], 1.0, g);
            }
        }
        if last > self.t0 {
            self.pairs(s, last - 1);
        }
        self.pairs(s, last);
    }
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
    let want = grad.is_some();
    ws.dq.resize(n, [0.0; 4]);
    ws.vel.resize(nv, Vel::default());
    ws.gq.resize(if want { n } else { 0 }, [0.0; 4]);
    let gu = match grad {
        Some(g) => {
            assert_eq!(g.len(), n, "one gradient entry per log-depth");
            g
        }
        None => &mut [],
    };
    let vt = w.v_target;
    let s = Shared {
        st,
        plan,
        u,
        grad: want,
        vt,
        ds: w.d_sep,
        c_speed: w.speed * w.scale,
        c_level: w.level * w.scale,
        c_acc: w.accel * w.scale / (vt * vt),
        c_align: w.align * w.scale,
        c_coh: w.cohesion * w.scale,
        c_sep: w.separation * w.scale,
    };
    let at = |starts: &[usize]| -> Vec<usize> { plan.chunks.iter().map(|&t| starts[t]).collect() };
    let (obs_at, vel_at) = (at(&plan.obs), at(&plan.vel));
    let grad_at = if want {
        obs_at.clone()
    } else {
        vec![0; obs_at.len()]
    };
    let mut chunks: Vec<Chunk> = split_at(&mut ws.dq, &obs_at)
        .into_iter()
        .zip(split_at(&mut ws.vel, &vel_at))
        .zip(split_at(&mut ws.gq, &grad_at))
        .zip(split_at(gu, &grad_at))
        .enumerate()
        .map(|(c, (((dq, vel), gq), gu))| Chunk {
            t0: plan.chunks[c],
            t1: plan.chunks[c + 1],
            o0: obs_at[c],
            v0: vel_at[c],
            dq,
            vel,
            gq,
            gu,
            sums: [0.0; 6],
            give_v: Vec::new(),
            give_q: Vec::new(),
        })
        .collect();
    if chunks.len() == 1 {
        chunks[0].sweep(&s);
        chunks[0].finish(&s, None);
    } else {
        chunks.par_iter_mut().for_each(|c| c.sweep(&s));
        let gives: Vec<_> = chunks
            .iter_mut()
            .map(|c| (std::mem::take(&mut c.give_v), std::mem::take(&mut c.give_q)))
            .collect();
        chunks
            .par_iter_mut()
            .enumerate()
            .for_each(|(k, c)| c.finish(&s, gives.get(k + 1)));
    }
    let sums = chunks.iter().fold([0.0; 6], |mut a, c| {
        for (x, y) in a.iter_mut().zip(c.sums) {
            *x += y;
        }
        a
    });
    SeqTerms {
        speed: s.c_speed * sums[0],
        level: s.c_level * sums[1],
        accel: s.c_acc * sums[2],
        align: s.c_align * sums[3],
        cohesion: s.c_coh * sums[4],
        separation: s.c_sep * sums[5],
    }
}
