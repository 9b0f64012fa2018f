//! Unrolling the model (paper §5): the steps of a run, each decide → forces → step, with the
//! decisions live or replayed, and per-step hooks for what changes between steps besides the
//! state (rapier's `PhysicsHooks`): a frame's leader guidance, per-agent forces, an extra force,
//! corrections after a step.

use super::{ForceTensors, HerdState, Model, Recording, StepDecisions};
use crate::data::AgentRow;
use crate::error::{Error, Result};
use crate::herd::sim::Guidance;
use burn::tensor::Tensor;
use herdfit_kernels::{NeighbourLists, P2};
use rand::Rng;

/// Where a rollout's no-gradient decisions come from.
pub enum Decide<'a, R: Rng> {
    /// Computed from the current state (and optionally appended to a recording).
    Live {
        rng: &'a mut R,
        record: Option<&'a mut Recording>,
    },
    /// Taken from a recording, step by step.
    Replay(&'a Recording),
}

/// What a run lets its caller change between steps. Every method has a default that changes
/// nothing, except [`StepHooks::after`], which sees each step's decisions and new state.
pub trait StepHooks {
    /// Before step `t` is decided: e.g. this frame's leader guidance.
    fn before_decide(&mut self, _t: usize, _model: &mut Model) -> Result<()> {
        Ok(())
    }

    /// The forces of step `t`, when not the run's own from θ (e.g. one parameter set per agent).
    fn forces(&mut self, _t: usize, _state: &HerdState) -> Result<Option<ForceTensors>> {
        Ok(None)
    }

    /// An extra force per agent added to F of eq. 3 in step `t` (the hook of §7.5), from the
    /// state the step was decided on.
    fn extra(&mut self, _t: usize, _state: &HerdState) -> Result<Option<Vec<P2>>> {
        Ok(None)
    }

    /// The state after step `t`, possibly corrected (e.g. kept out of obstacles); sees the
    /// step's decisions.
    fn after(&mut self, t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState>;
}

impl<T: StepHooks + ?Sized> StepHooks for Box<T> {
    fn before_decide(&mut self, t: usize, model: &mut Model) -> Result<()> {
        (**self).before_decide(t, model)
    }

    fn forces(&mut self, t: usize, state: &HerdState) -> Result<Option<ForceTensors>> {
        (**self).forces(t, state)
    }

    fn extra(&mut self, t: usize, state: &HerdState) -> Result<Option<Vec<P2>>> {
        (**self).extra(t, state)
    }

    fn after(&mut self, t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState> {
        (**self).after(t, dec, next)
    }
}

/// Hooks that only observe: `observe(t, dec, next)` after every step.
struct Observe<F>(F);

impl<F: FnMut(usize, &StepDecisions, &HerdState) -> Result<()>> StepHooks for Observe<F> {
    fn after(&mut self, t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState> {
        (self.0)(t, dec, &next)?;
        Ok(next)
    }
}

/// Hooks that set the leaders' guidance of every step (`guidance[t]` for step t) and observe.
pub struct Guided<'a, F> {
    pub guidance: &'a [Guidance],
    pub observe: F,
}

impl<F: FnMut(usize, &StepDecisions, &HerdState) -> Result<()>> StepHooks for Guided<'_, F> {
    fn before_decide(&mut self, t: usize, model: &mut Model) -> Result<()> {
        let g = self
            .guidance
            .get(t)
            .ok_or_else(|| Error::Internal(format!("no guidance for step {t} of the run")))?;
        model.world.guidance = g.clone();
        Ok(())
    }

    fn after(&mut self, t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState> {
        (self.observe)(t, dec, &next)?;
        Ok(next)
    }
}

impl Model {
    /// Unrolls `steps` steps from `state` with parameters `theta` (`[12]`). `observe(t, dec, next)`
    /// sees the decisions of step t and the state after it.
    pub fn rollout<R: Rng>(
        &self,
        theta: &Tensor<1>,
        state: HerdState,
        steps: usize,
        decide: Decide<'_, R>,
        observe: impl FnMut(usize, &StepDecisions, &HerdState) -> Result<()>,
    ) -> Result<HerdState> {
        self.run(theta, state, steps, decide, &mut Observe(observe))
    }

    /// [`Model::run`] from the herd `rows` with live decisions drawn from `rng` (none recorded).
    pub fn run_live<R: Rng>(
        &self,
        theta: &Tensor<1>,
        rows: &[AgentRow],
        steps: usize,
        rng: &mut R,
        hooks: &mut dyn StepHooks,
    ) -> Result<HerdState> {
        let state = HerdState::from_rows(rows, &theta.device());
        let decide = Decide::Live { rng, record: None };
        self.run(theta, state, steps, decide, hooks)
    }

    /// The decisions of `steps` live steps from the herd `rows` with parameters `theta`, drawn
    /// from `rng` and recorded for replay (no gradient is needed: run it on a plain device).
    pub fn record<R: Rng>(
        &self,
        theta: &Tensor<1>,
        rows: &[AgentRow],
        steps: usize,
        rng: &mut R,
    ) -> Result<Recording> {
        let mut rec = Recording::new(rows.len());
        let state = HerdState::from_rows(rows, &theta.device());
        let decide = Decide::Live {
            rng,
            record: Some(&mut rec),
        };
        self.rollout(theta, state, steps, decide, |_, _, _| Ok(()))?;
        Ok(rec)
    }

    /// [`Model::rollout`] with per-step [`StepHooks`]: step t decides (after
    /// `hooks.before_decide`, on a copy of this model), takes `hooks.forces` or those of θ and
    /// `hooks.extra`, steps, and `hooks.after` gives the state the next step starts from.
    pub fn run<R: Rng>(
        &self,
        theta: &Tensor<1>,
        mut state: HerdState,
        steps: usize,
        mut decide: Decide<'_, R>,
        hooks: &mut dyn StepHooks,
    ) -> Result<HerdState> {
        let mut model = self.clone();
        let f = ForceTensors::new(theta, &self.params.constants);
        if let Decide::Replay(rec) = &decide {
            if rec.steps.len() < steps || rec.agents != state.n() {
                return Err(Error::invalid(format!(
                    "the recording holds {} steps of {} agents; {steps} steps of {} requested",
                    rec.steps.len(),
                    rec.agents,
                    state.n()
                )));
            }
        }
        let mut lists = NeighbourLists::new(super::NEIGHBOUR_SKIN);
        for t in 0..steps {
            hooks.before_decide(t, &mut model)?;
            let live;
            let dec = match &mut decide {
                Decide::Replay(rec) => &rec.steps[t],
                Decide::Live { rng, record } => {
                    live = model.decide_with(&state.snapshot()?, *rng, &mut lists);
                    if let Some(r) = record {
                        r.steps.push(live.clone());
                    }
                    &live
                }
            };
            let own = hooks.forces(t, &state)?;
            let extra = hooks.extra(t, &state)?;
            let next =
                model.step_with(own.as_ref().unwrap_or(&f), &state, dec, extra.as_deref())?;
            state = hooks.after(t, dec, next)?;
        }
        Ok(state)
    }
}
