//! The visible pairs of one step in compressed rows (DESIGN §4.3): the input of the force kernel
//! of eq. 3–5 ([`crate::forces`]), built from the padded lists of a [`Perception`].

use crate::geometry::P2;
use crate::perception::Perception;

/// The visible pairs of one step in compressed rows (padding dropped), from a [`Perception`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PairLists {
    pub n: usize,
    /// `nb_start[i]..nb_start[i + 1]` index `nb` and `nb_branch` for agent i (`n + 1` entries).
    pub nb_start: Vec<u32>,
    pub nb: Vec<u32>,
    pub nb_branch: Vec<u8>,
    /// `ob_start[i]..ob_start[i + 1]` index `ob_point` and `ob_branch` for agent i.
    pub ob_start: Vec<u32>,
    pub ob_point: Vec<P2>,
    pub ob_branch: Vec<u8>,
}

impl PairLists {
    /// The real (unmasked) entries of the padded lists of `p`, in list order.
    pub fn from_perception(p: &Perception) -> Self {
        let (n, k, ko) = (p.n, p.k, p.ko);
        let real_nb = p.neighbour_mask.iter().filter(|&&m| m != 0).count();
        let real_ob = p.obstacle_mask.iter().filter(|&&m| m != 0).count();
        let mut out = PairLists {
            n,
            nb_start: Vec::with_capacity(n + 1),
            nb: Vec::with_capacity(real_nb),
            nb_branch: Vec::with_capacity(real_nb),
            ob_start: Vec::with_capacity(n + 1),
            ob_point: Vec::with_capacity(real_ob),
            ob_branch: Vec::with_capacity(real_ob),
        };
        out.nb_start.push(0);
        out.ob_start.push(0);
        for i in 0..n {
            let (rows, orows) = (i * k..(i + 1) * k, i * ko..(i + 1) * ko);
            match real_prefix(&p.neighbour_mask[rows.clone()]) {
                // Perception writes its rows as real entries, then padding: copy the prefix.
                Some(m) => {
                    out.nb.extend_from_slice(&p.neighbours[i * k..i * k + m]);
                    out.nb_branch
                        .extend_from_slice(&p.neighbour_branch[i * k..i * k + m]);
                }
                None => {
                    for s in rows.filter(|&s| p.neighbour_mask[s] != 0) {
                        out.nb.push(p.neighbours[s]);
                        out.nb_branch.push(p.neighbour_branch[s]);
                    }
                }
            }
            out.nb_start.push(out.nb.len() as u32);
            match real_prefix(&p.obstacle_mask[orows.clone()]) {
                Some(m) => {
                    out.ob_point
                        .extend_from_slice(&p.obstacle_points[i * ko..i * ko + m]);
                    out.ob_branch
                        .extend_from_slice(&p.obstacle_branch[i * ko..i * ko + m]);
                }
                None => {
                    for s in orows.filter(|&s| p.obstacle_mask[s] != 0) {
                        out.ob_point.push(p.obstacle_points[s]);
                        out.ob_branch.push(p.obstacle_branch[s]);
                    }
                }
            }
            out.ob_start.push(out.ob_point.len() as u32);
        }
        out
    }

    /// Number of agent–neighbour pairs.
    pub fn pairs(&self) -> usize {
        self.nb.len()
    }

    pub(crate) fn neighbours(&self, i: usize) -> std::ops::Range<usize> {
        self.nb_start[i] as usize..self.nb_start[i + 1] as usize
    }

    pub(crate) fn obstacles(&self, i: usize) -> std::ops::Range<usize> {
        self.ob_start[i] as usize..self.ob_start[i + 1] as usize
    }
}

/// `Some(m)` when the first `m` entries of a mask row are real and the rest padding.
#[inline]
fn real_prefix(mask: &[u8]) -> Option<usize> {
    let m = mask.iter().take_while(|&&v| v != 0).count();
    mask[m..].iter().all(|&v| v == 0).then_some(m)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows whose real entries are not a prefix (e.g. an edited recording) keep them all too.
    #[test]
    fn compact_lists_of_scattered_masks() {
        let p = Perception {
            n: 2,
            k: 3,
            neighbours: vec![1, 0, 1, 0, 0, 1],
            neighbour_mask: vec![0, 1, 1, 1, 0, 1],
            neighbour_branch: vec![0, 2, 3, 1, 0, 2],
            ko: 2,
            obstacle_points: vec![[0.0, 0.0], [5.0, 6.0], [7.0, 8.0], [1.0, 1.0]],
            obstacle_mask: vec![0, 1, 1, 0],
            obstacle_branch: vec![0, 1, 3, 0],
            front_count: vec![0, 0],
            density: vec![0.1, 0.1],
        };
        let l = PairLists::from_perception(&p);
        assert_eq!(l.nb_start, vec![0, 2, 4]);
        assert_eq!(l.nb, vec![0, 1, 0, 1]);
        assert_eq!(l.nb_branch, vec![2, 3, 1, 2]);
        assert_eq!(l.ob_start, vec![0, 1, 2]);
        assert_eq!(l.ob_point, vec![[5.0, 6.0], [7.0, 8.0]]);
        assert_eq!(l.ob_branch, vec![1, 3]);
    }
}
