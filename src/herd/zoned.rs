//! Runs with one parameter set per zone (paper §7.2.4): each step every agent takes the forces of
//! the set of the zone its cell lies in. [`ZoneSets`] holds the zones and their sets; [`Zoned`]
//! wraps any [`StepHooks`] so that a run (synth, validation) uses them.

use crate::data::Grid;
use crate::error::Result;
use crate::herd::params::{Params, N_PARAMS};
use crate::herd::sets::{NamedSet, ParamSets, PARAM_SETS_SCHEMA};
use crate::herd::sim::{ForceTensors, HerdState, Model, StepDecisions, StepHooks};
use crate::herd::zones::{ZoneSpec, Zones, ZonesFile, ZONES_SCHEMA};
use herdfit_kernels::P2;
use std::path::Path;

/// Zones assigned to a grid and one parameter set per zone.
#[derive(Clone, Debug)]
pub struct ZoneSets {
    pub zones: Zones,
    pub sets: Vec<Params>,
    pub grid: Grid,
}

impl ZoneSets {
    /// A bundle's sets with their polygons as zones of `grid` (obstacle cells `obstacles`
    /// excluded); errors name `path`.
    pub fn of_bundle(
        bundle: &ParamSets,
        path: &Path,
        grid: &Grid,
        obstacles: &ndarray::Array2<u8>,
    ) -> Result<ZoneSets> {
        let file = ZonesFile {
            schema: ZONES_SCHEMA.into(),
            mask: bundle.mask.clone(),
            zones: bundle
                .sets
                .iter()
                .map(|s| ZoneSpec {
                    name: s.name.clone(),
                    polygon: s.polygon.clone(),
                    colour: s.colour.clone(),
                    speed: s.speed,
                })
                .collect(),
        };
        let zones = Zones::of_file(file, path, grid, obstacles)?;
        Ok(ZoneSets {
            zones,
            sets: bundle.sets.iter().map(|s| s.params.clone()).collect(),
            grid: *grid,
        })
    }

    /// The bundle of these sets (each with its zone's polygon).
    pub fn bundle(&self, provenance: Option<serde_json::Value>) -> ParamSets {
        ParamSets {
            schema: PARAM_SETS_SCHEMA.into(),
            // Absolute, so that the bundle finds its mask from wherever it is read.
            mask: self
                .zones
                .mask
                .as_ref()
                .map(|m| std::fs::canonicalize(m).unwrap_or_else(|_| m.clone())),
            sets: self
                .zones
                .specs
                .iter()
                .zip(&self.sets)
                .map(|(z, p)| NamedSet {
                    name: z.name.clone(),
                    polygon: z.polygon.clone(),
                    colour: z.colour.clone(),
                    speed: z.speed,
                    params: p.clone(),
                })
                .collect(),
            provenance,
        }
    }

    /// The zone of each position (zone 0 outside the grid or on an obstacle cell).
    pub fn zone_of(&self, pos: &[P2]) -> Vec<usize> {
        pos.iter()
            .map(|&p| match self.grid.cell_of(p) {
                Some((ix, iy)) => self.zones.zone_of_cell((iy * self.grid.nx + ix) as i64),
                None => 0,
            })
            .collect()
    }

    /// The per-agent forces of a state (no gradient).
    pub fn forces(&self, state: &HerdState) -> Result<ForceTensors> {
        let zone = self.zone_of(&state.snapshot()?.pos);
        let thetas: Vec<[f64; N_PARAMS]> = zone.iter().map(|&z| self.sets[z].to_vec()).collect();
        let c = &self.sets[0].constants;
        Ok(ForceTensors::per_agent(&thetas, c, &state.x.device()))
    }
}

/// [`StepHooks`] `inner` with each agent's forces from its zone's set.
pub struct Zoned<'a, H> {
    pub inner: H,
    pub sets: &'a ZoneSets,
}

impl<H: StepHooks> StepHooks for Zoned<'_, H> {
    fn before_decide(&mut self, t: usize, model: &mut Model) -> Result<()> {
        self.inner.before_decide(t, model)
    }

    fn forces(&mut self, _t: usize, state: &HerdState) -> Result<Option<ForceTensors>> {
        self.sets.forces(state).map(Some)
    }

    fn extra(&mut self, t: usize, state: &HerdState) -> Result<Option<Vec<P2>>> {
        self.inner.extra(t, state)
    }

    fn after(&mut self, t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState> {
        self.inner.after(t, dec, next)
    }
}
