//! The fit loop's helpers: the replica herds between windows (refill, population control), the
//! fit-loss guard and the gradient read-back.

use super::config::FitConfig;
use super::run::Forward;
use crate::data::agents::AgentRow;
use crate::data::boundary::Gates;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::sim::{read_vec, Model};
use crate::herd::start::{population_control, population_control_open};
use crate::measure::fields::field_errors;
use burn::tensor::Tensor;
use rand_chacha::ChaCha8Rng;

/// The K replica herds of one clip in one epoch, with the next free id of each.
pub(super) struct Herds {
    pub(super) rows: Vec<Vec<AgentRow>>,
    pub(super) next_ids: Vec<u64>,
}

/// The fit-loss guard (issue #14): a NaN/inf loss or gradient stops the fit with one line naming
/// the epoch, the window and the likely cause, before the optimiser step, so θ, the checkpoint of
/// the last finished epoch and every output stay as they were (the optimiser's own rule would
/// otherwise take a random step past a non-finite gradient, §6.1).
pub(super) fn check_finite_step(
    epoch: usize,
    clip: usize,
    window: std::ops::Range<usize>,
    losses: [f64; 3],
    g: &[f64],
) -> Result<()> {
    let bad_loss = losses.iter().any(|v| !v.is_finite());
    let bad_grad = g.iter().position(|v| !v.is_finite());
    if !bad_loss && bad_grad.is_none() {
        return Ok(());
    }
    let what = match (bad_loss, bad_grad) {
        (true, _) => format!(
            "the loss is not finite (E_mean {}, E_var {}, E_fields {})",
            losses[0], losses[1], losses[2]
        ),
        (false, Some(p)) => format!("the gradient of parameter {p} is {}", g[p]),
        (false, None) => unreachable!("checked above"),
    };
    Err(Error::invalid(format!(
        "epoch {epoch}, clip #{clip}, window frames {}..{}: {what}; likely cause: extreme values in \
         the clip's fields (density, velocity, fps) or a step size (lr) too large for them; \
         the last finished epoch's checkpoint is kept",
        window.start, window.end
    )))
}

/// The gradient of `loss` with respect to `theta` (zeros where none reaches it): 12 values per
/// parameter set `theta` holds.
pub(super) fn grad_of(loss: Tensor<1>, theta: &Tensor<1>) -> Result<Vec<f64>> {
    let n = theta.dims()[0];
    let grads = loss.backward();
    Ok(theta
        .grad(&grads)
        .map(|t| read_vec(&t))
        .transpose()?
        .unwrap_or_else(|| vec![0.0; n]))
}

impl Herds {
    /// Every replica starts the next window from the tracked animals `rows` (`fit --tracks`).
    pub(super) fn start_from(&mut self, rows: &[AgentRow]) {
        let next = rows.iter().map(|a| a.id + 1).max().unwrap_or(0);
        for (r, n) in self.rows.iter_mut().zip(self.next_ids.iter_mut()) {
            *r = rows.to_vec();
            *n = next;
        }
    }

    /// A replica that lost every agent is restarted from the fields of frame `f`.
    pub(super) fn refill_empty(
        &mut self,
        clip: &ClipFields,
        f: usize,
        model: &Model,
        rng: &mut ChaCha8Rng,
    ) {
        for (rows, next_id) in self.rows.iter_mut().zip(self.next_ids.iter_mut()) {
            if rows.is_empty() {
                *rows = population_control(
                    clip,
                    f,
                    std::mem::take(rows),
                    0.0,
                    &model.params.speed,
                    next_id,
                    rng,
                );
            }
        }
    }

    /// After a window ending at frame `f`: each live replica's end state, detached, under
    /// population control; returns the replicas' mean density and velocity errors and their
    /// total agents.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn control(
        &mut self,
        clip: &ClipFields,
        gates: &Gates,
        f: usize,
        fwd: &Forward,
        cfg: &FitConfig,
        model: &Model,
        rng: &mut ChaCha8Rng,
    ) -> Result<(f64, f64, usize)> {
        let kr = fwd.live.len() as f64;
        let (mut de, mut ve, mut agents) = (0.0, 0.0, 0usize);
        for (k, &r) in fwd.live.iter().enumerate() {
            let ids: Vec<u64> = self.rows[r].iter().map(|x| x.id).collect();
            let rows = fwd.ends[k].clone().detach().rows(&ids)?;
            // A still's stationary fit is not rebalanced (§7.2.4): drift is what it measures.
            let threshold = match cfg.still {
                Some(_) => f64::INFINITY,
                None => cfg.density_threshold,
            };
            self.rows[r] = if gates.is_open() {
                // Entrants cross their gate within the next window.
                let ahead = cfg.window as f64 * model.dt;
                population_control_open(
                    clip,
                    gates,
                    f,
                    rows,
                    threshold,
                    &model.params.speed,
                    &mut self.next_ids[r],
                    rng,
                    ahead,
                )
                .0
            } else {
                population_control(
                    clip,
                    f,
                    rows,
                    threshold,
                    &model.params.speed,
                    &mut self.next_ids[r],
                    rng,
                )
            };
            let (d, v) = field_errors(clip, f, &self.rows[r]);
            de += d / kr;
            ve += v / kr;
            agents += self.rows[r].len();
        }
        Ok((de, ve, agents))
    }
}
