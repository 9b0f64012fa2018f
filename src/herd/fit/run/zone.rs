//! The zone fit (paper §7.2.4): one parameter set per zone, learnt jointly through the fit loop
//! of [`super`], and its loss without learning (the global phase's score).

use super::{epoch_rng, mean_losses, resume, save_checkpoint, CheckpointDir, FitRun, ZoneStarts};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::fit::config::FitConfig;
use crate::herd::fit::log::LogRow;
use crate::herd::params::Params;
use crate::herd::zones::Zones;
use crate::progress::Proceed;

/// The result of a zone fit: one parameter set per zone (in the zones' order) and the log (its
/// `theta` is zone 0's).
#[derive(Clone, Debug)]
pub struct ZoneFitResult {
    pub sets: Vec<Params>,
    pub log: Vec<LogRow>,
}

/// A zone fit (paper §7.2.4): one parameter set per zone of `zones`, learnt jointly — every
/// step each agent uses the set of the zone its cell lies in ([`crate::herd::sim::ForceTensors::zoned`]), so one
/// window's gradient reaches every zone's set through the agents that used it, and each set
/// takes its own optimiser step. `starts[k]` is zone k's start. With `ckpt`, every zone's set and
/// optimiser state is checkpointed after every epoch, and a resume continues exactly.
pub fn fit_zones<R: Proceed>(
    clip: &ClipFields,
    starts: &[Params],
    cfg: &FitConfig,
    zones: &Zones,
    ckpt: Option<&CheckpointDir>,
    progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<ZoneFitResult> {
    zone_fit_inner(clip, starts, cfg, zones, ckpt, true, progress)
}

/// The loss of per-zone sets (`sets[k]` for zone k) on a clip without learning, as
/// [`super::loss_of`] for one set: one epoch of [`fit_zones`]'s schedule with no updates.
pub fn zone_loss_of(
    clip: &ClipFields,
    sets: &[Params],
    cfg: &FitConfig,
    zones: &Zones,
) -> Result<(f64, f64, f64)> {
    let one = FitConfig {
        epochs: 1,
        ..cfg.clone()
    };
    let r = zone_fit_inner(clip, sets, &one, zones, None, false, |_, _, _, _| {})?;
    Ok(mean_losses(&r.log))
}

/// [`fit_zones`], or with `learn` false its schedule without updates (whose frames need not hold
/// every zone's agents: nothing is learnt there).
fn zone_fit_inner<R: Proceed>(
    clip: &ClipFields,
    starts: &[Params],
    cfg: &FitConfig,
    zones: &Zones,
    ckpt: Option<&CheckpointDir>,
    learn: bool,
    mut progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<ZoneFitResult> {
    if starts.len() != zones.len() || starts.is_empty() {
        return Err(Error::Internal(format!(
            "{} starts for {} zones",
            starts.len(),
            zones.len()
        )));
    }
    if learn {
        zones.check_agents(clip, cfg.frames.clone())?;
    }
    let clips = [clip];
    let mut run = FitRun::new(&clips, &starts[0], cfg, learn)?;
    run.zones = Some(zones);
    let zs = ZoneStarts {
        names: zones.specs.iter().map(|z| z.name.clone()).collect(),
        starts: starts[1..].iter().map(Params::to_vec).collect(),
    };
    let start = starts[0].to_vec();
    let (mut learnt, first_epoch) = resume(ckpt, cfg, start, &zs)?;
    for epoch in first_epoch..cfg.epochs {
        let mut rng = epoch_rng(cfg.seed, epoch);
        run.epoch_on_clip(epoch, 0, &mut learnt, &mut rng, &mut progress)?;
        if let Some(c) = ckpt {
            save_checkpoint(c, epoch + 1, &learnt, cfg, start, &zs)?;
        }
    }
    let thetas = std::iter::once(learnt.theta).chain(learnt.zones.iter().map(|(t, _)| *t));
    let sets = thetas
        .zip(starts)
        .map(|(t, s)| {
            let mut p = s.with_vec(&t);
            p.speed = run.params.speed.clone();
            p
        })
        .collect();
    Ok(ZoneFitResult {
        sets,
        log: learnt.log,
    })
}
