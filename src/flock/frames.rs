//! The frames of an animation (Klotsman & Tal Algorithm 1 line 9 and §6's hand-over): the
//! initiation's frames renumbered by slot, the quintic hand-over to the first key shape, the
//! steady frames from the key-shape timeline, the track rows and per-frame savings (eq. 1).

use super::initiation::{InitiationRun, Target};
use super::power;
use super::steady::Timeline;
use crate::data::tracks::TrackRow;
use crate::progress::Progress;

/// Offsets of the hand-over: quintic with h(0) = δ, h'(0) = w, h''(0) = 0 and h = h' = h'' = 0
/// at T. Returns (h, h') at τ ∈ [0, T].
fn hand_over(delta: f64, w: f64, t: f64, big_t: f64) -> (f64, f64) {
    if t >= big_t {
        return (0.0, 0.0);
    }
    let s = t / big_t;
    // Hermite quintic basis: H0 for the value, H1 for the slope (times T).
    let h0 = 1.0 - 10.0 * s.powi(3) + 15.0 * s.powi(4) - 6.0 * s.powi(5);
    let h1 = s - 6.0 * s.powi(3) + 8.0 * s.powi(4) - 3.0 * s.powi(5);
    let d0 = (-30.0 * s.powi(2) + 60.0 * s.powi(3) - 30.0 * s.powi(4)) / big_t;
    let d1 = (1.0 - 18.0 * s.powi(2) + 32.0 * s.powi(3) - 15.0 * s.powi(4)) / big_t;
    (delta * h0 + w * big_t * h1, delta * d0 + w * big_t * d1)
}

/// Second derivatives of the quintic's two basis functions at s = τ/T (times T² for the value's,
/// T for the slope's): h''(τ) = δ H0''(s)/T² + w H1''(s)/T.
fn hand_over_curvature(s: f64) -> (f64, f64) {
    (
        -60.0 * s + 180.0 * s * s - 120.0 * s * s * s,
        -36.0 * s + 96.0 * s * s - 60.0 * s * s * s,
    )
}

/// The peak acceleration (wingspans/s²) of the hand-over quintics with offsets `delta` and
/// relative velocities `w` when the hand-over lasts `big_t` seconds (sampled at 1/400 of it).
pub(super) fn hand_over_peak(delta: &[[f64; 2]], w: &[[f64; 2]], big_t: f64) -> f64 {
    let mut peak: f64 = 0.0;
    for k in 0..=400 {
        let (c0, c1) = hand_over_curvature(k as f64 / 400.0);
        let (a0, a1) = (c0 / (big_t * big_t), c1 / big_t);
        for (d, v) in delta.iter().zip(w) {
            peak = peak.max((d[0] * a0 + v[0] * a1).hypot(d[1] * a0 + v[1] * a1));
        }
    }
    peak
}

/// The shortest hand-over (at least 1 s, in steps of 1 %) whose quintics keep every bird's
/// acceleration within `a_max` (wingspans/s²): the peak of δ H0''/T² + w H1''/T is not monotone
/// in T when δ and w point against each other, so T grows until the sampled peak, with 1 % of
/// margin for the sampling, is within the bound.
pub(super) fn hand_over_time(delta: &[[f64; 2]], w: &[[f64; 2]], a_max: f64) -> f64 {
    let mut t = 1.0;
    while hand_over_peak(delta, w, t) > 0.99 * a_max && t < 1e4 {
        t *= 1.01;
    }
    t
}

/// Assigns each initiation bird a distinct slot: its own where the slots are a bijection, else
/// the nearest free target position (greedy, in bird order).
#[allow(clippy::needless_range_loop)]
fn assign_slots(run: &InitiationRun, target: &Target) -> Vec<usize> {
    let n = target.pos.len();
    let last = run.frames.last().map(|f| f.as_slice()).unwrap_or(&[]);
    let mut taken = vec![false; n];
    let mut slot = vec![usize::MAX; n];
    for (i, s) in run.slots.iter().enumerate() {
        if let Some(t) = s {
            if !taken[*t] {
                taken[*t] = true;
                slot[i] = *t;
            }
        }
    }
    let leader = run.slots.iter().position(|s| *s == Some(0)).unwrap_or(0);
    let l = last.get(leader).map_or([0.0, 0.0], |b| b.pos);
    for i in 0..n {
        if slot[i] != usize::MAX {
            continue;
        }
        let p = last.get(i).map_or([0.0, 0.0], |b| b.pos);
        let best = (0..n).filter(|&t| !taken[t]).min_by(|&a, &b| {
            let d = |t: usize| {
                (p[0] - l[0] - target.pos[t][0] + target.pos[0][0])
                    .hypot(p[1] - l[1] - target.pos[t][1] + target.pos[0][1])
            };
            d(a).total_cmp(&d(b))
        });
        if let Some(t) = best {
            taken[t] = true;
            slot[i] = t;
        }
    }
    slot
}

/// Positions, headings (unit vectors) and velocities (wingspans/s) per frame.
#[derive(Default)]
pub(super) struct Frames {
    pub(super) pos: Vec<Vec<[f64; 2]>>,
    pub(super) headings: Vec<Vec<[f64; 2]>>,
    pub(super) vels: Vec<Vec<[f64; 2]>>,
}

/// Where the initiation hands over: the first key shape's origin in the world, and each slot's
/// offset δ from its place and relative velocity w at the hand-over.
pub(super) struct HandOver {
    pub(super) origin: [f64; 2],
    pub(super) delta: Vec<[f64; 2]>,
    pub(super) w: Vec<[f64; 2]>,
    pub(super) frames: usize,
}

/// The initiation frames (birds renumbered by their final slot) and the hand-over state.
pub(super) fn initiation_frames(
    run: Option<&InitiationRun>,
    target: &Target,
    n: usize,
    fps: f64,
    v: f64,
    out: &mut Frames,
) -> HandOver {
    let Some(r) = run else {
        return HandOver {
            origin: [0.0, 0.0],
            delta: vec![[0.0; 2]; n],
            w: vec![[0.0; 2]; n],
            frames: 0,
        };
    };
    let slot = assign_slots(r, target);
    for f in &r.frames[..r.frames.len() - 1] {
        let mut p = vec![[0.0; 2]; n];
        let mut h = vec![[0.0; 2]; n];
        let mut vv = vec![[0.0; 2]; n];
        for (i, b) in f.iter().enumerate() {
            p[slot[i]] = b.pos;
            h[slot[i]] = b.dir();
            vv[slot[i]] = [b.dir()[0] * b.v * fps, b.dir()[1] * b.v * fps];
        }
        out.pos.push(p);
        out.headings.push(h);
        out.vels.push(vv);
    }
    let last = r.frames.last().unwrap();
    let mut pl = [0.0; 2];
    for (i, b) in last.iter().enumerate() {
        if slot[i] == 0 {
            pl = b.pos;
        }
    }
    let origin = [pl[0] - target.pos[0][0], pl[1] - target.pos[0][1]];
    let mut delta = vec![[0.0; 2]; n];
    let mut w = vec![[0.0; 2]; n];
    for (i, b) in last.iter().enumerate() {
        let t = slot[i];
        delta[t] = [
            b.pos[0] - origin[0] - target.pos[t][0],
            b.pos[1] - origin[1] - target.pos[t][1],
        ];
        let d = b.dir();
        w[t] = [d[0] * b.v * fps, d[1] * b.v * fps - v];
    }
    HandOver {
        origin,
        delta,
        w,
        frames: r.frames.len() - 1,
    }
}

/// The steady frames: the timeline in the flock frame moving at `v`, plus the hand-over
/// offsets decaying over `hand_s` seconds; the timeline starts when the hand-over ends (its first
/// key shape is held until then).
#[allow(clippy::too_many_arguments)]
pub(super) fn steady_frames(
    timeline: &Timeline,
    ho: &HandOver,
    hand_s: f64,
    n: usize,
    count: usize,
    fps: f64,
    v: f64,
    out: &mut Frames,
    progress: &mut dyn Progress,
) {
    let (origin, delta, w) = (ho.origin, &ho.delta, &ho.w);
    progress.start("frames", count as u64);
    for k in 0..count {
        let t = k as f64 / fps;
        let (rel, relv) = timeline.at((t - hand_s).max(0.0));
        let mut p = vec![[0.0; 2]; n];
        let mut vv = vec![[0.0; 2]; n];
        for i in 0..n {
            let (hx, dhx) = hand_over(delta[i][0], w[i][0], t, hand_s);
            let (hy, dhy) = hand_over(delta[i][1], w[i][1], t, hand_s);
            p[i] = [
                origin[0] + rel[i][0] + hx,
                origin[1] + v * t + rel[i][1] + hy,
            ];
            vv[i] = [relv[i][0] + dhx, v + relv[i][1] + dhy];
        }
        out.headings.push(
            vv.iter()
                .map(|u| {
                    let l = u[0].hypot(u[1]).max(1e-12);
                    [u[0] / l, u[1] / l]
                })
                .collect(),
        );
        out.pos.push(p);
        out.vels.push(vv);
        progress.inc(1);
    }
    progress.finish();
}

/// Track rows (metres, altitude `z`) for every frame; savings (e, ξ) and each bird's mean e
/// over the steady frames, from frame `first_steady` on (after the hand-over).
#[allow(clippy::type_complexity)]
pub(super) fn rows_and_savings(
    fr: &Frames,
    z: &[f64],
    wingspan_m: f64,
    fps: f64,
    first_steady: usize,
) -> (Vec<TrackRow>, Vec<(u64, f64, u64, f64, f64)>, Vec<f64>) {
    let n = z.len();
    let mut rows = Vec::with_capacity(fr.pos.len() * n);
    let mut savings = Vec::new();
    let mut sums = vec![0.0; n];
    let mut counted = 0usize;
    for (f, (p, vv)) in fr.pos.iter().zip(&fr.vels).enumerate() {
        let time = f as f64 / fps;
        let leader = (0..n)
            .max_by(|&a, &b| p[a][1].total_cmp(&p[b][1]))
            .unwrap_or(0);
        for i in 0..n {
            rows.push(TrackRow {
                frame: f as u64,
                time,
                id: i as u64,
                pos: [p[i][0] * wingspan_m, p[i][1] * wingspan_m, z[i]],
                vel: Some([vv[i][0] * wingspan_m, vv[i][1] * wingspan_m, 0.0]),
                role: Some(if i == leader { "leader" } else { "follower" }.into()),
            });
        }
        if f >= first_steady && power::check_lateral(p).is_ok() {
            let e = power::savings_unchecked(p);
            let xi = power::relative(&e);
            for i in 0..n {
                savings.push((f as u64, time, i as u64, e[i], xi[i]));
                sums[i] += e[i];
            }
            counted += 1;
        }
    }
    let mean_saving: Vec<f64> = sums.iter().map(|s| s / counted.max(1) as f64).collect();
    (rows, savings, mean_saving)
}

/// Largest acceleration (second differences, wingspans/s²) of any bird over frames
/// `from..to`.
#[allow(clippy::needless_range_loop)]
pub(super) fn max_accel(frames: &[Vec<[f64; 2]>], fps: f64, from: usize, to: usize) -> f64 {
    let mut m: f64 = 0.0;
    for f in from.max(1)..to.min(frames.len().saturating_sub(1)) {
        for i in 0..frames[f].len() {
            let ax =
                (frames[f + 1][i][0] - 2.0 * frames[f][i][0] + frames[f - 1][i][0]) * fps * fps;
            let ay =
                (frames[f + 1][i][1] - 2.0 * frames[f][i][1] + frames[f - 1][i][1]) * fps * fps;
            m = m.max(ax.hypot(ay));
        }
    }
    m
}
