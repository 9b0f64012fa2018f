//! Runs of the model on a clip: the model of a clip (its obstacles and frame rate) and runs from
//! a frame's fields with the leaders following the clip's guidance.

use crate::backend::{cpu_device, Precision};
use crate::data::boundary::Gates;
use crate::data::AgentRow;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::boundary::{Crossings, Open, Stream};
use crate::herd::params::{Params, SpeedModel};
use crate::herd::sim::StepHooks;
use crate::herd::sim::{
    obstacle_map, theta_tensor, Guidance, Guided, HerdState, Model, StepDecisions, World,
};
use crate::herd::start::{start_herd, Settle};
use crate::measure::fields::field_errors;
use burn::tensor::Device;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::cell::RefCell;
use std::ops::Range;
use std::rc::Rc;

/// The model of a clip: its obstacle cells, its frame rate, and `params` (the guidance is set per
/// frame by the caller).
pub fn clip_model(params: Params, clip: &ClipFields) -> Model {
    let g = clip.grid();
    Model {
        params,
        world: World {
            obstacles: Some(obstacle_map(&g, &clip.obstacles)),
            guidance: Guidance::None,
            fixed_speed: None,
        },
        dt: 1.0 / clip.meta.fps,
        force_kernel: crate::herd::sim::ForceKernel::default(),
    }
}

/// A run from the fields of frame `first` of a clip to frame `last` with `params` under the clip's
/// speed model (leaders follow `guidance[f]`, the guidance of every frame; no population
/// control): the herd is drawn from the fields with seed `seed` and settled by `settle`, then
/// `observe(f, state, ids)` sees it at every frame `f` in `first + 1 ..= last`. Returns the herd
/// it started from.
#[allow(clippy::too_many_arguments)]
pub fn run_from_fields(
    clip: &ClipFields,
    params: &Params,
    range: (usize, usize),
    seed: u64,
    settle: &Settle,
    guidance: &[Guidance],
    device: &Device,
    observe: impl FnMut(usize, &HerdState, &[u64]) -> Result<()>,
) -> Result<Vec<AgentRow>> {
    let closed = Gates::closed();
    run_from(
        clip, params, None, None, &closed, range, seed, settle, guidance, device, observe,
    )
    .map(|(rows, _)| rows)
}

/// [`run_from_fields`], with each agent's forces from its zone's set when `zones` is given
/// (`params` still gives the speed model and the constants), started from the animals
/// `tracked` in frame `first` when given (`fit`/`validate --tracks`) instead of a herd drawn from
/// that frame's fields, and with the clip's open boundary `gates` (agents leave through the edge
/// of the grid, new ones enter at the entry gates: [`crate::herd::boundary`]; closed gates change
/// nothing). `observe` sees the agents present after each step. Returns the herd it started from
/// and what crossed the boundary.
#[allow(clippy::too_many_arguments)]
pub fn run_from(
    clip: &ClipFields,
    params: &Params,
    zones: Option<&crate::herd::zoned::ZoneSets>,
    tracked: Option<&[AgentRow]>,
    gates: &Gates,
    (first, last): (usize, usize),
    seed: u64,
    settle: &Settle,
    guidance: &[Guidance],
    device: &Device,
    mut observe: impl FnMut(usize, &HerdState, &[u64]) -> Result<()>,
) -> Result<(Vec<AgentRow>, Crossings)> {
    let mut params = params.clone();
    params.speed = SpeedModel::of_clip(clip, &params.speed);
    let mut model = clip_model(params, clip);
    if let Some(z) = zones {
        model.world.fixed_speed = z.zones.speed_map(&z.grid);
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rows = match tracked {
        Some(t) => t.to_vec(),
        None => start_herd(&model, clip, first, settle, &mut rng, device)?,
    };
    if rows.is_empty() {
        return Err(Error::invalid(format!(
            "frame {first} of the clip holds no agents: nothing to start from"
        )));
    }
    let ids = Rc::new(RefCell::new(
        rows.iter().map(|r| r.id).collect::<Vec<u64>>(),
    ));
    let theta = theta_tensor(&model.params.to_vec(), device);
    let steps = last.min(guidance.len()).saturating_sub(first);
    let seen = ids.clone();
    let hooks = Guided {
        guidance: &guidance[first.min(guidance.len())..],
        observe: |t: usize, _: &StepDecisions, next: &HerdState| {
            observe(first + t + 1, next, &seen.borrow())
        },
    };
    // The zones' forces, then the boundary: each wraps the hooks inside it.
    let mut hooks: Box<dyn StepHooks + '_> = match zones {
        None => Box::new(hooks),
        Some(sets) => Box::new(crate::herd::zoned::Zoned { inner: hooks, sets }),
    };
    if !gates.is_open() {
        model.run_live(&theta, &rows, steps, &mut rng, hooks.as_mut())?;
        return Ok((rows, Crossings::default()));
    }
    let next_id = rows.iter().map(|r| r.id + 1).max().unwrap_or(0);
    let mut open = Open {
        inner: hooks,
        stream: Stream::new(clip, gates, model.params.speed.clone(), seed, next_id),
        first,
        dt: model.dt,
        ids,
        device: device.clone(),
    };
    model.run_live(&theta, &rows, steps, &mut rng, &mut open)?;
    Ok((rows, open.stream.crossings))
}

/// The mean density and velocity errors ([`field_errors`]) over the frames after the first of a
/// [`run_from`] through the frames `range` of the clip, started from the animals `tracked` in its
/// first frame when given, through the clip's boundary `gates`.
#[allow(clippy::too_many_arguments)]
pub fn evaluate(
    clip: &ClipFields,
    params: &Params,
    tracked: Option<&[AgentRow]>,
    gates: &Gates,
    range: Range<usize>,
    seed: u64,
    precision: Precision,
    settle: &Settle,
    guidance: &[Guidance],
) -> Result<(f64, f64)> {
    let device = cpu_device(precision)?;
    let (mut de, mut ve, mut n): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let last = range.end.saturating_sub(1);
    run_from(
        clip,
        params,
        None,
        tracked,
        gates,
        (range.start, last),
        seed,
        settle,
        guidance,
        &device,
        |f, state, ids| {
            let (d, v) = field_errors(clip, f, &state.rows(ids)?);
            de += d;
            ve += v;
            n += 1.0;
            Ok(())
        },
    )?;
    Ok((de / n.max(1.0), ve / n.max(1.0)))
}
