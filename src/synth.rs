//! Synthetic clips with known truth: simulate the herd model with given parameters, rasterise the
//! trajectories into clip fields, keep the parameters as `truth.json`.

use crate::backend::Precision;
use crate::error::{Error, Result};
use crate::fields::{rasterise, ClipFields, Grid};
use crate::io::{push_traj_frame, AgentRow, TRAJ_HEADER};
use crate::params::Params;
use crate::sim::{random_herd, theta_tensor, Decide, Guidance, HerdSpec, HerdState, Model, World};
use herdfit_kernels::ObstacleMap;
use ndarray::Array2;
use rand::SeedableRng;
use serde::Deserialize;
use std::path::Path;

/// Obstacle cells file: `{"cells": [[ix, iy], …]}` (row 0 at the bottom).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CellsFile {
    cells: Vec<[i64; 2]>,
}

/// Reads an obstacle-cells file for an `nx × ny` grid.
pub fn read_cells(path: &Path, nx: usize, ny: usize) -> Result<Array2<u8>> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let f: CellsFile = serde_json::from_str(&text)
        .map_err(|e| Error::file(path, format!("expected {{\"cells\": [[ix, iy], …]}}: {e}")))?;
    let mut m = Array2::<u8>::zeros((ny, nx));
    for (k, &[ix, iy]) in f.cells.iter().enumerate() {
        if ix < 0 || iy < 0 || ix as usize >= nx || iy as usize >= ny {
            return Err(Error::file(
                path,
                format!("cells[{k}] = [{ix}, {iy}] is outside the {nx}×{ny} grid"),
            ));
        }
        m[[iy as usize, ix as usize]] = 1;
    }
    Ok(m)
}

/// Settings of a synthetic clip.
#[derive(Clone, Debug)]
pub struct SynthConfig {
    pub params: Params,
    pub agents: usize,
    pub frames: usize,
    pub fps: f64,
    pub grid: Grid,
    pub obstacles: Array2<u8>,
    pub seed: u64,
    /// Direction of travel (and of the uniform guidance), degrees from +x.
    pub heading_deg: f64,
    pub precision: Precision,
}

/// A synthetic clip: the fields, the trajectories (one list per frame) and their CSV text.
pub struct Synth {
    pub clip: ClipFields,
    pub frames: Vec<Vec<AgentRow>>,
    pub roles: Vec<Vec<bool>>,
}

/// The obstacle map of the simulation from the clip's obstacle cells.
pub fn obstacle_map(grid: &Grid, obstacles: &Array2<u8>) -> ObstacleMap {
    let mut m = ObstacleMap::empty(grid.origin, grid.cell_size, grid.nx, grid.ny);
    for ((iy, ix), &v) in obstacles.indexed_iter() {
        m.blocked[iy * grid.nx + ix] = v != 0;
    }
    m
}

/// Runs the model with the known parameters: a herd crossing the field behind a uniform guidance
/// direction, starting upstream of the grid's centre.
pub fn synthesise(
    cfg: &SynthConfig,
    device: &burn::tensor::Device,
    mut progress: impl FnMut(),
) -> Result<Synth> {
    if cfg.agents == 0 {
        return Err(Error::invalid("the herd is empty: --agents must be ≥ 1"));
    }
    if cfg.frames == 0 {
        return Err(Error::invalid("--frames must be ≥ 1"));
    }
    if !(cfg.fps.is_finite() && cfg.fps > 0.0) {
        return Err(Error::invalid(format!("--fps {} must be > 0", cfg.fps)));
    }
    let g = &cfg.grid;
    if g.nx == 0 || g.ny == 0 || !(g.cell_size.is_finite() && g.cell_size > 0.0) {
        return Err(Error::invalid(
            "the grid must have ≥ 1 cell and a cell size > 0",
        ));
    }
    let a = cfg.heading_deg.to_radians();
    let dir = [a.cos(), a.sin()];
    let size = g.size();
    let centre = [g.origin[0] + size[0] / 2.0, g.origin[1] + size[1] / 2.0];
    let spec = HerdSpec {
        agents: cfg.agents,
        density: 0.5,
        centre: [
            centre[0] - 0.2 * size[0] * dir[0],
            centre[1] - 0.2 * size[1] * dir[1],
        ],
        heading_deg: cfg.heading_deg,
        heading_spread_deg: 20.0,
    };
    let world = World {
        obstacles: Some(obstacle_map(g, &cfg.obstacles)),
        guidance: Guidance::Uniform(dir),
    };
    let init = random_herd(&spec, &cfg.params.speed, &world, cfg.seed)?;
    let ids: Vec<u64> = init.iter().map(|r| r.id).collect();
    let model = Model {
        params: cfg.params.clone(),
        world,
        dt: 1.0 / cfg.fps,
        force_kernel: crate::sim::ForceKernel::default(),
    };
    let theta = theta_tensor(&model.params.to_vec(), device);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x005e_ed0f_5eed);
    let mut frames = vec![init.clone()];
    let mut roles = Vec::with_capacity(cfg.frames);
    let end = model.rollout(
        &theta,
        HerdState::from_rows(&init, device),
        cfg.frames - 1,
        Decide::Live {
            rng: &mut rng,
            record: None,
        },
        |_, dec, next| {
            roles.push(dec.leader.clone());
            frames.push(next.rows(&ids)?);
            progress();
            Ok(())
        },
    )?;
    roles.push(model.decide(&end.snapshot()?, &mut rng).leader);
    let provenance = serde_json::json!({
        "source": "synth",
        "agents": cfg.agents,
        "seed": cfg.seed,
        "heading_deg": cfg.heading_deg,
        "precision": cfg.precision,
        "truth": "truth.json",
    });
    let clip = rasterise(&frames, *g, cfg.fps, cfg.obstacles.clone(), provenance)?;
    Ok(Synth {
        clip,
        frames,
        roles,
    })
}

impl Synth {
    /// The trajectories as `frame,time,id,x,y,vx,vy,role` CSV.
    pub fn trajectories_csv(&self, fps: f64) -> String {
        let mut s = String::with_capacity(64 * self.frames.len() * self.frames[0].len() + 64);
        s.push_str(TRAJ_HEADER);
        s.push('\n');
        for (f, (rows, roles)) in self.frames.iter().zip(&self.roles).enumerate() {
            push_traj_frame(&mut s, f, f as f64 / fps, rows, roles);
        }
        s
    }
}
