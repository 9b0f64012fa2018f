//! Perception and the references (Klotsman & Tal §6.1, §6.2.1 side determination and target
//! distances, §6.2.2 separation) and side balancing (module docs of `initiation`).

use super::super::extract::Side;
use super::super::hpr;
use super::{dist, Bird, Initiation};

impl Initiation {
    /// Candidate references of bird `i` in order of preference (§6.1): visible birds within the
    /// reference volume by distance, then the other visible birds by distance.
    pub(super) fn preferences(&self, i: usize) -> Vec<usize> {
        let b = &self.birds[i];
        let d = b.dir();
        let eye = self.cfg.eye_field_deg.to_radians();
        let refv = self.cfg.reference_field_deg.to_radians();
        let mut cand = Vec::new();
        let mut pts = Vec::new();
        for (j, o) in self.birds.iter().enumerate() {
            if j == i {
                continue;
            }
            let r = [o.pos[0] - b.pos[0], o.pos[1] - b.pos[1]];
            let ang = (d[0] * r[1] - d[1] * r[0])
                .atan2(d[0] * r[0] + d[1] * r[1])
                .abs();
            if ang <= eye && (r[0] != 0.0 || r[1] != 0.0) {
                cand.push((j, ang, r[0].hypot(r[1])));
                pts.push(o.pos);
            }
        }
        let vis = hpr::visible_2d(b.pos, &pts, self.cfg.hpr_pad);
        let mut inner: Vec<(usize, f64)> = Vec::new();
        let mut outer: Vec<(usize, f64)> = Vec::new();
        for (k, &(j, ang, r)) in cand.iter().enumerate() {
            if vis[k] {
                if ang <= refv {
                    inner.push((j, r));
                } else {
                    outer.push((j, r));
                }
            }
        }
        let by = |a: &(usize, f64), b: &(usize, f64)| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0));
        inner.sort_by(by);
        outer.sort_by(by);
        inner.into_iter().chain(outer).map(|(j, _)| j).collect()
    }

    fn leads_to(refs: &[Option<usize>], from: usize, to: usize) -> bool {
        let mut c = Some(from);
        for _ in 0..=refs.len() {
            match c {
                Some(x) if x == to => return true,
                Some(x) => c = refs[x],
                None => return false,
            }
        }
        true
    }

    /// Sides (§6.2.1): a follower of a bird without a side (the leader) takes the side it is on
    /// relative to it; others take their reference's side.
    pub(super) fn sides(&self, refs: &[Option<usize>], leader: usize) -> Vec<Option<Side>> {
        let n = self.birds.len();
        let mut sides: Vec<Option<Option<Side>>> = vec![None; n];
        sides[leader] = Some(None);
        fn side_of(
            i: usize,
            refs: &[Option<usize>],
            birds: &[Bird],
            switching: &[Option<Side>],
            memo: &mut Vec<Option<Option<Side>>>,
            depth: usize,
        ) -> Option<Side> {
            if let Some(s) = memo[i] {
                return s;
            }
            let s = match (switching[i], refs[i]) {
                (Some(s), _) => Some(s),
                (None, None) => None,
                (None, Some(j)) => {
                    let sj = if depth > refs.len() {
                        None
                    } else {
                        side_of(j, refs, birds, switching, memo, depth + 1)
                    };
                    sj.or(Some(if birds[i].pos[0] > birds[j].pos[0] {
                        Side::Right
                    } else {
                        Side::Left
                    }))
                }
            };
            memo[i] = Some(s);
            s
        }
        (0..n)
            .map(|i| side_of(i, refs, &self.birds, &self.switching, &mut sides, 0))
            .collect()
    }

    /// References after the separation drive (§6.2.2): of two birds following the same bird (on
    /// the same side, for the leader) within `separation_distance` of each other, the rear one
    /// takes its next preference; references that would close a cycle are skipped.
    pub(super) fn references(&self, leader: usize) -> Vec<Option<usize>> {
        let n = self.birds.len();
        let prefs: Vec<Vec<usize>> = (0..n)
            .map(|i| {
                if i == leader {
                    return vec![];
                }
                let mut p = self.preferences(i);
                // Keep last step's reference first while it is still visible.
                if let Some(j) = self.prev_refs[i] {
                    if let Some(k) = p.iter().position(|&c| c == j) {
                        p.remove(k);
                        p.insert(0, j);
                    }
                }
                p
            })
            .collect();
        let mut pick = vec![0usize; n];
        let mut refs: Vec<Option<usize>> = vec![None; n];
        let choose = |i: usize, pick: &mut Vec<usize>, refs: &mut Vec<Option<usize>>| {
            refs[i] = None;
            while pick[i] < prefs[i].len() {
                let c = prefs[i][pick[i]];
                if !Self::leads_to(refs, c, i) {
                    refs[i] = Some(c);
                    return;
                }
                pick[i] += 1;
            }
        };
        // Front birds choose first, so cycles are broken at their rear-most bird.
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| self.birds[b].pos[1].total_cmp(&self.birds[a].pos[1]));
        for &i in &order {
            if i != leader {
                choose(i, &mut pick, &mut refs);
            }
        }
        for _ in 0..3 * n {
            let sides = self.sides(&refs, leader);
            let mut changed = false;
            for &f in &order {
                let Some(j) = refs[f] else { continue };
                if self.switching[f].is_some() {
                    continue;
                }
                // A bird in front of f with the same reference (and side, at the leader), near.
                let clash = order.iter().take_while(|&&o| o != f).any(|&o| {
                    refs[o] == Some(j)
                        && (j != leader || sides[o] == sides[f])
                        && dist(self.birds[o].pos, self.birds[f].pos)
                            <= self.cfg.separation_distance
                });
                if clash {
                    pick[f] += 1;
                    choose(f, &mut pick, &mut refs);
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        refs
    }

    /// Target slots (§6.2.1 target distances): the leader takes slot 0; a bird whose reference
    /// has a slot takes the next slot on its side.
    pub(super) fn slots(
        &self,
        refs: &[Option<usize>],
        sides: &[Option<Side>],
        leader: usize,
    ) -> Vec<Option<usize>> {
        let n = self.birds.len();
        let mut slots: Vec<Option<Option<usize>>> = vec![None; n];
        slots[leader] = Some(Some(0));
        for _ in 0..n {
            let mut progress = false;
            for i in 0..n {
                if slots[i].is_some() {
                    continue;
                }
                let (Some(j), Some(s)) = (refs[i], sides[i]) else {
                    continue;
                };
                if let Some(sj) = slots[j] {
                    slots[i] = Some(sj.and_then(|t| self.target.next(t, s)));
                    progress = true;
                }
            }
            if !progress {
                break;
            }
        }
        slots.into_iter().map(|s| s.flatten()).collect()
    }

    /// Side balancing (module docs): starts and ends side switches; returns overridden
    /// references for switching birds.
    #[allow(clippy::needless_range_loop)]
    pub(super) fn balance(&mut self, refs: &mut [Option<usize>], leader: usize) {
        let n = self.birds.len();
        let sides = self.sides(refs, leader);
        let slots = self.slots(refs, &sides, leader);
        let mut taken = vec![false; n];
        for t in slots.iter().flatten() {
            taken[*t] = true;
        }
        for s in [Side::Left, Side::Right] {
            let other = if s == Side::Left {
                Side::Right
            } else {
                Side::Left
            };
            // End of the other side's chain: its deepest taken slot's bird.
            let mut end_slot = 0;
            while let Some(nx) = self.target.next(end_slot, other) {
                if !taken[nx] {
                    break;
                }
                end_slot = nx;
            }
            let free = self.target.next(end_slot, other).is_some();
            let end_bird = (0..n)
                .find(|&i| slots[i] == Some(end_slot))
                .unwrap_or(leader);
            // Switching birds already heading there follow the chain's end.
            let mut heading_there = 0;
            for i in 0..n {
                if self.switching[i] == Some(other) {
                    heading_there += 1;
                    refs[i] = Some(end_bird).filter(|&e| e != i);
                }
            }
            let count = |side: Side| sides.iter().filter(|x| **x == Some(side)).count();
            let want = |side: Side| match side {
                Side::Left => self.target.nl,
                Side::Right => self.target.nr,
            };
            if !free || heading_there > 0 || count(s) <= want(s) || count(other) >= want(other) {
                continue;
            }
            // Rear-most bird on side s beyond the end of its chain, followed by nobody.
            let beyond = (0..n)
                .filter(|&i| {
                    i != leader
                        && sides[i] == Some(s)
                        && slots[i].is_none()
                        && refs[i].is_some()
                        && !refs.contains(&Some(i))
                        && self.switching[i].is_none()
                })
                .min_by(|&a, &b| self.birds[a].pos[1].total_cmp(&self.birds[b].pos[1]));
            if let Some(b) = beyond {
                self.switching[b] = Some(other);
                self.switch_since[b] = self.steps;
                refs[b] = Some(end_bird);
            }
        }
    }
}
