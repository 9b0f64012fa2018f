//! Runs of the model on a clip: the model of a clip (its obstacles and frame rate) and runs from
//! a frame's fields with the leaders following the clip's guidance.

use crate::backend::{cpu_device, Precision};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::sim::{
    obstacle_map, theta_tensor, ForceTensors, Guidance, HerdState, Model, World,
};
use crate::herd::start::{start_herd, Settle};
use crate::measure::fields::field_errors;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::ops::Range;

/// The model of a clip: its obstacle cells, its frame rate, and `params` (the guidance is set per
/// frame by the caller).
pub fn clip_model(params: Params, clip: &ClipFields) -> Model {
    let g = clip.grid();
    Model {
        params,
        world: World {
            obstacles: Some(obstacle_map(&g, &clip.obstacles)),
            guidance: Guidance::None,
        },
        dt: 1.0 / clip.meta.fps,
    }
}

/// Simulates the frames `range` of the clip from its first frame's fields with `params`
/// (leaders following the clip's velocity field, no population control) and returns the mean
/// density and velocity errors over the frames after the first. `guidance` holds the leaders'
/// guidance of every frame ([`crate::herd::guidance::guidance_fields`]).
pub fn evaluate(
    clip: &ClipFields,
    params: &Params,
    range: Range<usize>,
    seed: u64,
    precision: Precision,
    settle: &Settle,
    guidance: &[Guidance],
) -> Result<(f64, f64)> {
    let device = cpu_device(precision)?;
    let mut model = clip_model(params.clone(), clip);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rows = start_herd(&model, clip, range.start, settle, &mut rng, &device)?;
    if rows.is_empty() {
        return Err(Error::invalid("the first frame holds no agents"));
    }
    let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
    let theta = theta_tensor(&params.to_vec(), &device);
    let f = ForceTensors::new(&theta, &params.constants);
    let mut state = HerdState::from_rows(&rows, &device);
    let (mut de, mut ve, mut n): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let last = range.end.saturating_sub(1);
    for (fr, lead) in guidance.iter().enumerate().take(last).skip(range.start) {
        let snap = state.snapshot()?;
        model.world.guidance = lead.clone();
        let dec = model.decide(&snap, &mut rng);
        state = model.step(&f, &state, &dec)?;
        let (d, v) = field_errors(clip, fr + 1, &state.rows(&ids)?);
        de += d;
        ve += v;
        n += 1.0;
    }
    Ok((de / n.max(1.0), ve / n.max(1.0)))
}
