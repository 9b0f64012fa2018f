//! How much of a simulation started from a clip's *fields* is the start itself?
//!
//! On a synthetic clip (`herdfit synth`, which keeps the agents in trajectories.csv and the truth
//! in truth.json) this runs the true parameters from frame `FRAME` four ways and prints the herd's
//! polarization (eq. 12) every 10 frames beside the clip's own:
//!
//! - `true agents`: the clip's agents at that frame;
//! - `fields`: the herd the fit and `validate` start from ([`init_herd`]);
//! - `fields + settle`: the same, settled ([`settle`], `--settle N` of `fit` and `validate`);
//! - `true positions`: the clip's positions with the headings and speeds sampled from the fields;
//! - `true agents, σ = ∞`: the clip's agents, the leaders guided by the herd's mean direction
//!   rather than by each cell's mean velocity ([`guidance_field`]'s scale).
//!
//! Beside the polarization it prints the herd's radius of gyration (BL) every 10 frames.
//!
//! ```text
//! herdfit synth --agents 300 --frames 120 --grid 14x10 --cell-size 4 --seed 7 --out /tmp/syn
//! cargo run --release --example init_bias -- /tmp/syn 60 200
//! ```
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::agents::AgentRow;
use herdfit::data::ClipFields;
use herdfit::herd::fit::{clip_model, guidance_field, init_herd, settle, Settle};
use herdfit::herd::params::Params;
use herdfit::herd::sim::{theta_tensor, ForceTensors, HerdState};
use herdfit::measure::emergent::polarization;
use rand::SeedableRng;
use std::path::PathBuf;

fn polar(rows: &[AgentRow]) -> f64 {
    let v: Vec<[f64; 2]> = rows.iter().map(|r| [r.vx, r.vy]).collect();
    polarization(&v, &vec![1.0; rows.len()])
}

/// Radius of gyration of the herd (BL).
fn gyration(rows: &[AgentRow]) -> f64 {
    let n = rows.len() as f64;
    let mx = rows.iter().map(|r| r.x).sum::<f64>() / n;
    let my = rows.iter().map(|r| r.y).sum::<f64>() / n;
    (rows
        .iter()
        .map(|r| (r.x - mx).powi(2) + (r.y - my).powi(2))
        .sum::<f64>()
        / n)
        .sqrt()
}

/// Every 10th value, rounded to `digits` decimals.
fn every10(v: &[f64], digits: i32) -> Vec<f64> {
    let k = 10f64.powi(digits);
    v.iter().step_by(10).map(|x| (x * k).round() / k).collect()
}

fn main() -> anyhow::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        anyhow::bail!("usage: init_bias CLIP/ FRAME [SETTLE_ITERATIONS]");
    }
    let dir = PathBuf::from(&args[1]);
    let start: usize = args[2].parse()?;
    let settle_n: usize = args.get(3).map_or(Ok(200), |s| s.parse())?;
    let clip = ClipFields::load(&dir)?;
    let truth = Params::load(&dir.join("truth.json"))?;
    let mut truth_rows: Vec<Vec<AgentRow>> = vec![Vec::new(); clip.frames()];
    let text = std::fs::read_to_string(dir.join("trajectories.csv"))?;
    for l in text.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        let f: usize = c[0].parse()?;
        truth_rows[f].push(AgentRow {
            id: c[2].parse()?,
            x: c[3].parse()?,
            y: c[4].parse()?,
            vx: c[5].parse()?,
            vy: c[6].parse()?,
        });
    }
    if start + 1 >= clip.frames() {
        anyhow::bail!("FRAME must be below {}", clip.frames() - 1);
    }
    let device = cpu_device(Precision::F32)?;
    let mut params = truth.clone();
    params.speed = herdfit::herd::params::SpeedModel::of_clip(&clip, &params.speed);
    let model = clip_model(params.clone(), &clip);
    let g = clip.grid();
    let clip_pol: Vec<f64> = (start..clip.frames())
        .map(|k| polar(&truth_rows[k]))
        .collect();
    let clip_gyr: Vec<f64> = (start..clip.frames())
        .map(|k| gyration(&truth_rows[k]))
        .collect();
    println!("{:<20} polarization {:?}", "clip", every10(&clip_pol, 3));
    println!("{:<20} gyration     {:?}", "", every10(&clip_gyr, 2));
    for mode in [
        "true agents",
        "fields",
        "fields + settle",
        "true positions",
        "true agents, σ = ∞",
    ] {
        let scale = if mode.ends_with('∞') {
            f64::INFINITY
        } else {
            0.0
        };
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut rows = match mode {
            "true agents" | "true agents, σ = ∞" => truth_rows[start].clone(),
            _ => init_herd(&clip, start, &params.speed, &mut rng),
        };
        if mode == "fields + settle" {
            let cfg = Settle {
                iterations: settle_n,
                ..Default::default()
            };
            settle(&model, &clip, &mut rows, &cfg, &device)?;
        }
        if mode == "true positions" {
            // Same counts per cell by construction: take the clip's positions cell by cell.
            let mut by_cell: std::collections::BTreeMap<(usize, usize), Vec<&AgentRow>> =
                Default::default();
            for r in &truth_rows[start] {
                if let Some(c) = g.cell_of([r.x, r.y]) {
                    by_cell.entry(c).or_default().push(r);
                }
            }
            for r in rows.iter_mut() {
                if let Some(t) = g
                    .cell_of([r.x, r.y])
                    .and_then(|c| by_cell.get_mut(&c))
                    .and_then(|v| v.pop())
                {
                    r.x = t.x;
                    r.y = t.y;
                }
            }
        }
        let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
        let mut m = model.clone();
        let th = theta_tensor(&params.to_vec(), &device);
        let forces = ForceTensors::new(&th, &params.constants);
        let mut state = HerdState::from_rows(&rows, &device);
        let mut pol = vec![polar(&rows)];
        let mut gyr = vec![gyration(&rows)];
        for fr in start..clip.frames() - 1 {
            m.world.guidance = guidance_field(&clip, fr, scale);
            let dec = m.decide(&state.snapshot()?, &mut rng);
            state = m.step(&forces, &state, &dec)?;
            let now = state.rows(&ids)?;
            pol.push(polar(&now));
            gyr.push(gyration(&now));
        }
        println!("{mode:<20} polarization {:?}", every10(&pol, 3));
        println!("{:<20} gyration     {:?}", "", every10(&gyr, 2));
    }
    Ok(())
}
