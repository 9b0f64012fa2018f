//! A behaviour's raw learnt samples and their thinning to `max_samples` (deterministic), keeping
//! the links of each sample to the next one of its track ([`super::action::ActionSamples::next`])
//! that survive.

use super::action::NO_NEXT;
use super::features::V2;

/// Raw (unprojected, weighted) state–action samples of one behaviour.
pub struct RawSamples {
    pub dims: usize,
    pub states: Vec<f64>,
    pub actions: Vec<V2>,
    /// Each sample's successor in its track ([`super::action::ActionSamples::next`]).
    pub next: Vec<u32>,
}

/// Samples kept together when thinning for continuation: runs of this many consecutive samples
/// (a track's steps over 3.2 s at 2.5 Hz) keep most of their links.
pub const THIN_RUN: usize = 8;

/// Keeps at most `max` samples, evenly spaced through them (deterministic); with `runs`, evenly
/// spaced runs of [`THIN_RUN`] consecutive samples, so that a track's kept steps still link to
/// their next ones (continuation).
pub fn thin(raw: &mut RawSamples, max: usize, runs: bool) {
    let n = raw.actions.len();
    if n <= max {
        return;
    }
    let d = raw.dims;
    let keep: Vec<usize> = if runs && max >= THIN_RUN {
        let r = max / THIN_RUN;
        (0..r)
            .flat_map(|i| {
                let start = i * n / r;
                start..(start + THIN_RUN).min(n)
            })
            .collect()
    } else {
        (0..max).map(|i| i * n / max).collect()
    };
    let states = keep
        .iter()
        .flat_map(|&i| raw.states[i * d..(i + 1) * d].iter().copied())
        .collect();
    let actions = keep.iter().map(|&i| raw.actions[i]).collect();
    // A kept sample's successor survives only when it was kept too.
    let mut kept_as = vec![NO_NEXT; n];
    for (new, &i) in keep.iter().enumerate() {
        kept_as[i] = new as u32;
    }
    let next = keep
        .iter()
        .map(|&i| match raw.next.get(i) {
            Some(&j) if j != NO_NEXT => kept_as[j as usize],
            _ => NO_NEXT,
        })
        .collect();
    raw.states = states;
    raw.actions = actions;
    raw.next = next;
}
