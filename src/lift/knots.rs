//! The unknowns of the whole sequence's coarse levels (see [`super::sequence::whole_sequence`]):
//! a bird's segments, log-depths linear between knots along each segment, and the problem on every
//! `stride`-th frame that the coarsest levels are evaluated on.

use super::observe::Observations;

/// Segments (a bird's run of consecutive frames): each one's observations in frame order.
pub fn segments(obs: &Observations) -> Vec<Vec<usize>> {
    (0..obs.len())
        .filter(|&i| obs.prev[i].is_none())
        .map(|start| {
            let mut run = vec![start];
            while let Some(n) = obs.next[*run.last().expect("non-empty")] {
                run.push(n);
            }
            run
        })
        .collect()
}

/// Log-depths as linear interpolation between knots along each segment: knots every `spacing`
/// frames from the segment's start and at its end (`spacing` 0: one knot per segment, a constant).
pub(super) struct Knots {
    /// The first knot of each segment, and their number last.
    first: Vec<usize>,
    /// Per observation: the knots it lies between and the weight of the second.
    k0: Vec<usize>,
    k1: Vec<usize>,
    w1: Vec<f64>,
    /// The observation at each knot.
    pub(super) at: Vec<usize>,
}

impl Knots {
    pub(super) fn new(segs: &[Vec<usize>], n: usize, spacing: usize) -> Knots {
        let (mut k0, mut k1, mut w1) = (vec![0; n], vec![0; n], vec![0.0; n]);
        let mut at = Vec::new();
        let mut firsts = Vec::with_capacity(segs.len() + 1);
        for run in segs {
            let first = at.len();
            firsts.push(first);
            let len = run.len();
            let pos: Vec<usize> = if spacing == 0 {
                vec![0]
            } else {
                let mut p: Vec<usize> = (0..len).step_by(spacing).collect();
                if *p.last().expect("non-empty") != len - 1 {
                    p.push(len - 1);
                }
                p
            };
            at.extend(pos.iter().map(|&p| run[p]));
            let mut j = 0;
            for (k, &o) in run.iter().enumerate() {
                while j + 1 < pos.len() && pos[j + 1] <= k {
                    j += 1;
                }
                if j + 1 < pos.len() {
                    let (a, b) = (pos[j], pos[j + 1]);
                    k0[o] = first + j;
                    k1[o] = first + j + 1;
                    w1[o] = (k - a) as f64 / (b - a) as f64;
                } else {
                    k0[o] = first + j;
                    k1[o] = first + j;
                }
            }
        }
        firsts.push(at.len());
        Knots {
            first: firsts,
            k0,
            k1,
            w1,
            at,
        }
    }

    /// Log-depths `u` of every observation from the knots' values `x` (element-wise, in parallel
    /// chunks).
    pub(super) fn interpolate(&self, x: &[f64], u: &mut [f64]) {
        use rayon::prelude::*;
        u.par_chunks_mut(CHUNK).enumerate().for_each(|(c, us)| {
            for (k, ui) in us.iter_mut().enumerate() {
                let i = c * CHUNK + k;
                *ui = (1.0 - self.w1[i]) * x[self.k0[i]] + self.w1[i] * x[self.k1[i]];
            }
        });
    }

    /// ∂E/∂x from ∂E/∂u (the transpose of [`Knots::interpolate`]), written into `g`: segment by
    /// segment in parallel (a segment's knots take only its observations' terms, added in frame
    /// order whatever the thread count).
    pub(super) fn pull_back(&self, segs: &[Vec<usize>], gu: &[f64], g: &mut [f64]) {
        use rayon::prelude::*;
        let mut parts = Vec::with_capacity(segs.len());
        let mut rest = g;
        for w in self.first.windows(2) {
            let (mine, tail) = rest.split_at_mut(w[1] - w[0]);
            parts.push((w[0], mine));
            rest = tail;
        }
        parts
            .into_par_iter()
            .zip(segs.par_iter())
            .for_each(|((first, gs), run)| {
                gs.iter_mut().for_each(|v| *v = 0.0);
                for &i in run {
                    let gi = gu[i];
                    gs[self.k0[i] - first] += (1.0 - self.w1[i]) * gi;
                    gs[self.k1[i] - first] += self.w1[i] * gi;
                }
            });
    }
}

/// Observations per chunk of the parallel element-wise passes.
const CHUNK: usize = 16_384;

/// The problem on every `stride`-th frame: the observations whose frame is the first frame plus a
/// multiple of `stride`, each linked to the same bird `stride` frames before and after when its
/// segment holds every frame between (a velocity of eq. 3.3 over `stride` frames).
pub(super) struct Coarse {
    pub(super) obs: Observations,
    /// The full problem's index of each observation.
    full: Vec<usize>,
    /// The full problem's segments, each as its kept observations (in this problem's indices;
    /// empty for a segment shorter than `stride` that holds no kept frame).
    pub(super) segs: Vec<Vec<usize>>,
}

impl Coarse {
    /// Every `stride`-th frame of `obs`, whose segments are `segs`.
    pub(super) fn new(obs: &Observations, segs: &[Vec<usize>], stride: usize) -> Coarse {
        let stride = stride.max(1) as u64;
        let first = obs.frames.first().map_or(0, |f| f.0);
        let full: Vec<usize> = (0..obs.len())
            .filter(|&i| (obs.frame[i] - first) % stride == 0)
            .collect();
        let mut sub_of = vec![usize::MAX; obs.len()];
        for (j, &i) in full.iter().enumerate() {
            sub_of[i] = j;
        }
        let hop = |mut i: usize, step: &dyn Fn(usize) -> Option<usize>| {
            for _ in 0..stride {
                i = step(i)?;
            }
            Some(sub_of[i])
        };
        let prev = full.iter().map(|&i| hop(i, &|k| obs.prev[k])).collect();
        let next = full.iter().map(|&i| hop(i, &|k| obs.next[k])).collect();
        let mut frames: Vec<(u64, std::ops::Range<usize>)> = Vec::new();
        for (j, &i) in full.iter().enumerate() {
            match frames.last_mut() {
                Some((f, r)) if *f == obs.frame[i] => r.end = j + 1,
                _ => frames.push((obs.frame[i], j..j + 1)),
            }
        }
        let sub = Observations {
            camera: obs.camera.clone(),
            fps: obs.fps / stride as f64,
            frame: full.iter().map(|&i| obs.frame[i]).collect(),
            time: full.iter().map(|&i| obs.time[i]).collect(),
            id: full.iter().map(|&i| obs.id[i]).collect(),
            pixel: full.iter().map(|&i| obs.pixel[i]).collect(),
            ray: full.iter().map(|&i| obs.ray[i]).collect(),
            prev,
            next,
            frames,
            birds: obs.birds,
        };
        let segs = segs
            .iter()
            .map(|run| {
                run.iter()
                    .filter(|&&i| sub_of[i] != usize::MAX)
                    .map(|&i| sub_of[i])
                    .collect()
            })
            .collect();
        Coarse {
            obs: sub,
            full,
            segs,
        }
    }

    /// `knots` (of the full problem's segments) seen from this problem's observations: the same
    /// unknowns, interpolated only where this problem has an observation.
    pub(super) fn knots(&self, knots: &Knots) -> Knots {
        Knots {
            first: knots.first.clone(),
            k0: self.full.iter().map(|&i| knots.k0[i]).collect(),
            k1: self.full.iter().map(|&i| knots.k1[i]).collect(),
            w1: self.full.iter().map(|&i| knots.w1[i]).collect(),
            at: knots.at.clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::boids::{synth_flock, BoidsConfig};
    use super::super::sequence::{energy_terms, whole_sequence};
    use super::super::{demo_config, frame::frame_by_frame, project_tracks};
    use super::*;
    use crate::progress::NoProgress;

    /// A 12-bird flock whose birds leave and enter a 40° view: its observations and true depths.
    fn flock() -> (Observations, Vec<f64>, super::super::LiftConfig) {
        let b = BoidsConfig::demo();
        let syn = synth_flock(&b, &mut NoProgress).unwrap();
        let (tracks, depth) = project_tracks(&syn.truth, &syn.camera, true).unwrap();
        let obs = Observations::new(&tracks, &syn.camera).unwrap();
        (obs, depth, demo_config(&b))
    }

    #[test]
    fn the_coarse_problem_links_each_bird_stride_frames_apart_within_its_segment() {
        let (obs, _, _) = flock();
        let segs = segments(&obs);
        let c = Coarse::new(&obs, &segs, 4);
        let first = obs.frames[0].0;
        assert_eq!(c.obs.len(), c.full.len());
        assert_eq!(c.segs.iter().map(Vec::len).sum::<usize>(), c.obs.len());
        let mut links = 0;
        for (j, &i) in c.full.iter().enumerate() {
            assert_eq!((obs.frame[i] - first) % 4, 0);
            assert_eq!((c.obs.id[j], c.obs.ray[j]), (obs.id[i], obs.ray[i]));
            // Four links back in the full problem exist exactly when the coarse one does.
            let mut back = Some(i);
            for _ in 0..4 {
                back = back.and_then(|k| obs.prev[k]);
            }
            assert_eq!(c.obs.prev[j].map(|p| c.full[p]), back);
            if let Some(p) = c.obs.prev[j] {
                assert_eq!(c.obs.next[p], Some(j));
                assert_eq!(c.obs.frame[p] + 4, c.obs.frame[j]);
                links += 1;
            }
        }
        assert!(links > c.obs.len() / 2, "{links} links");
        // Its frames are the kept ones, in order, each range over its observations.
        for (f, r) in &c.obs.frames {
            assert!(r.clone().all(|j| c.obs.frame[j] == *f));
        }
        assert_eq!(c.obs.frames.last().unwrap().1.end, c.obs.len());
    }

    #[test]
    fn stride_1_is_the_full_problem_and_the_knots_seen_from_it_are_the_same() {
        let (obs, depth, cfg) = flock();
        let segs = segments(&obs);
        let c = Coarse::new(&obs, &segs, 1);
        assert_eq!(c.full, (0..obs.len()).collect::<Vec<_>>());
        assert_eq!((&c.obs.prev, &c.obs.next), (&obs.prev, &obs.next));
        assert_eq!(c.segs, segs);
        assert_eq!(
            energy_terms(&c.obs, &depth, &cfg).unwrap(),
            energy_terms(&obs, &depth, &cfg).unwrap()
        );
        let k = Knots::new(&segs, obs.len(), 16);
        let seen = c.knots(&k);
        let x: Vec<f64> = (0..k.at.len()).map(|j| 4.0 + 0.01 * j as f64).collect();
        let (mut a, mut b) = (vec![0.0; obs.len()], vec![0.0; obs.len()]);
        k.interpolate(&x, &mut a);
        seen.interpolate(&x, &mut b);
        assert_eq!(a, b);
    }

    #[test]
    fn coarse_levels_on_every_4th_frame_still_beat_constant_depth() {
        let (obs, truth, mut cfg) = flock();
        cfg.sequence.coarse_stride = 4;
        let init = frame_by_frame(&obs, &cfg, &mut NoProgress).unwrap();
        let (depth, log) = whole_sequence(&obs, &init, &cfg, &mut NoProgress).unwrap();
        assert_eq!(log.strides, [4, 4, 4, 1, 1]);
        let rmse = |d: &dyn Fn(usize) -> f64| {
            let n = truth.len() as f64;
            ((0..truth.len())
                .map(|i| (d(i) - truth[i]).powi(2))
                .sum::<f64>()
                / n)
                .sqrt()
        };
        let mid = 0.5 * (cfg.near() + cfg.far());
        let (seq, constant) = (rmse(&|i| depth[i]), rmse(&|_| mid));
        assert!(seq < 0.5 * constant, "{seq} m vs {constant} m");
        assert!(depth.iter().all(|d| (cfg.near()..=cfg.far()).contains(d)));
        assert!(log.end.total < 1e-3 * log.start.total, "{log:?}");
    }
}
