//! Perception and the references (Klotsman & Tal §6.1, §6.2.1 side determination and target
//! distances, §6.2.2 separation), with the chain rules of the module docs of `initiation`.

use super::super::extract::Side;
use super::super::hpr;
use super::{dist, Initiation};

fn other(s: Side) -> Side {
    match s {
        Side::Left => Side::Right,
        Side::Right => Side::Left,
    }
}

impl Initiation {
    /// Candidate references of bird `i` in order of preference (§6.1): visible birds within the
    /// reference volume by distance, then the other visible birds by distance, then (chain
    /// rules: a bird that finds no free reference ahead searches) the birds visible within the
    /// visual volume widened by `keep_margin_deg`, then the birds HPR hides there, each by
    /// distance. The second list: the birds `i` may keep as
    /// its reference, visible within that widened volume (hysteresis: a bird abreast of or
    /// ahead of its reference sits on or beyond the volume's edge).
    pub(super) fn preferences(&self, i: usize) -> (Vec<usize>, Vec<usize>) {
        let b = &self.birds[i];
        let d = b.dir();
        let eye = self.cfg.eye_field_deg.to_radians();
        let wide = (self.cfg.eye_field_deg + self.cfg.keep_margin_deg)
            .min(180.0)
            .to_radians();
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
            if ang <= wide && (r[0] != 0.0 || r[1] != 0.0) {
                cand.push((j, ang, r[0].hypot(r[1])));
                pts.push(o.pos);
            }
        }
        let vis = hpr::visible_2d(b.pos, &pts, self.cfg.hpr_pad);
        let mut inner: Vec<(usize, f64)> = Vec::new();
        let mut outer: Vec<(usize, f64)> = Vec::new();
        let mut around: Vec<(usize, f64)> = Vec::new();
        let mut hidden: Vec<(usize, f64)> = Vec::new();
        let mut keep = Vec::new();
        for (k, &(j, ang, r)) in cand.iter().enumerate() {
            if !vis[k] {
                hidden.push((j, r));
            } else {
                keep.push(j);
                if ang <= refv {
                    inner.push((j, r));
                } else if ang <= eye {
                    outer.push((j, r));
                } else {
                    around.push((j, r));
                }
            }
        }
        let by = |a: &(usize, f64), b: &(usize, f64)| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0));
        inner.sort_by(by);
        outer.sort_by(by);
        around.sort_by(by);
        hidden.sort_by(by);
        let prefs = inner.into_iter().chain(outer).chain(around).chain(hidden);
        (prefs.map(|(j, _)| j).collect(), keep)
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

    /// The side bird `i` takes behind `j` (§6.2.1): `j`'s side when it has one, else the side
    /// `i` is on relative to `j` — except that a bird that already followed the leader on a side
    /// keeps it (hysteresis, module docs).
    fn side_behind(&self, i: usize, j: usize, sides: &[Option<Side>], leader: usize) -> Side {
        if j == leader && self.prev_refs[i] == Some(leader) {
            if let Some(s) = self.prev_sides[i] {
                return s;
            }
        }
        if j != leader {
            if let Some(s) = sides[j] {
                return s;
            }
        }
        if self.birds[i].pos[0] > self.birds[j].pos[0] {
            Side::Right
        } else {
            Side::Left
        }
    }

    /// Sides and target slots of the chains hanging from the leader (§6.2.1 side determination
    /// and target distances), dropping the links that break the chain rules: a second follower
    /// of a bird (of the leader on one side) — the rear one goes (§6.2.2) — and a follower
    /// beyond the end of its side's chain, and links off the leader's chains.
    fn structure(
        &self,
        refs: &mut [Option<usize>],
        leader: usize,
    ) -> (Vec<Option<Side>>, Vec<Option<usize>>) {
        let n = self.birds.len();
        let mut sides: Vec<Option<Side>> = vec![None; n];
        let mut slots: Vec<Option<usize>> = vec![None; n];
        let mut followers: Vec<Vec<usize>> = vec![Vec::new(); n];
        for (i, r) in refs.iter().enumerate() {
            if let Some(j) = *r {
                followers[j].push(i);
            }
        }
        // Front birds first, so that of two followers of one bird the rear one is dropped.
        for f in &mut followers {
            f.sort_by(|&a, &b| {
                self.birds[b].pos[1]
                    .total_cmp(&self.birds[a].pos[1])
                    .then(a.cmp(&b))
            });
        }
        slots[leader] = Some(0);
        let mut queue = vec![leader];
        let mut done = vec![false; n];
        done[leader] = true;
        while let Some(j) = queue.pop() {
            let mut used: Vec<Side> = Vec::new();
            for &i in &followers[j] {
                let mut s = self.side_behind(i, j, &sides, leader);
                // At the leader, a follower whose side is taken or empty in the target takes
                // the other side (chain rules).
                if j == leader && (used.contains(&s) || self.target.next(0, s).is_none()) {
                    s = other(s);
                }
                let next = slots[j].and_then(|t| self.target.next(t, s));
                if used.contains(&s) || (j != leader && !used.is_empty()) || next.is_none() {
                    refs[i] = None;
                    continue;
                }
                used.push(s);
                sides[i] = Some(s);
                slots[i] = next;
                done[i] = true;
                queue.push(i);
            }
        }
        // Links off the leader's chains are dropped: a reference must be matched (chain rules).
        for (r, d) in refs.iter_mut().zip(&done) {
            if !d {
                *r = None;
            }
        }
        (sides, slots)
    }

    /// References (§6.1) under the separation drive (§6.2.2) and the chain rules (module docs):
    /// a bird keeps last step's reference while it sees it and the link keeps the rules; birds
    /// without one choose, front-most first, the first of their preferences that no other bird
    /// follows (the leader: on that side) and that is matched to the target shape (§6.2.1) with
    /// a free place behind it on their side.
    /// Returns the references, sides and target slots.
    #[allow(clippy::type_complexity)]
    pub(super) fn references(
        &self,
        leader: usize,
    ) -> (Vec<Option<usize>>, Vec<Option<Side>>, Vec<Option<usize>>) {
        let n = self.birds.len();
        let (prefs, keep): (Vec<Vec<usize>>, Vec<Vec<usize>>) = (0..n)
            .map(|i| {
                if i == leader {
                    (vec![], vec![])
                } else {
                    self.preferences(i)
                }
            })
            .unzip();
        let mut refs: Vec<Option<usize>> = (0..n)
            .map(|i| self.prev_refs[i].filter(|j| i != leader && *j != i && keep[i].contains(j)))
            .collect();
        let mut order: Vec<usize> = (0..n).filter(|&i| i != leader).collect();
        order.sort_by(|&a, &b| {
            self.birds[b].pos[1]
                .total_cmp(&self.birds[a].pos[1])
                .then(a.cmp(&b))
        });
        let mut tried = vec![false; n];
        loop {
            let (sides, slots) = self.structure(&mut refs, leader);
            let Some(&i) = order.iter().find(|&&i| refs[i].is_none() && !tried[i]) else {
                return (refs, sides, slots);
            };
            tried[i] = true;
            refs[i] = prefs[i].iter().copied().find(|&c| {
                if Self::leads_to(&refs, c, i) {
                    return false;
                }
                let taken_on = |s: Side| {
                    (0..n).any(|o| {
                        o != i && refs[o] == Some(c) && (c != leader || sides[o] == Some(s))
                    })
                };
                let mut s = self.side_behind(i, c, &sides, leader);
                if c == leader && (taken_on(s) || self.target.next(0, s).is_none()) {
                    s = other(s);
                }
                let taken = taken_on(s);
                let room = slots[c].is_some_and(|t| self.target.next(t, s).is_some());
                !taken && room && dist(self.birds[i].pos, self.birds[c].pos) > 0.0
            });
        }
    }
}
