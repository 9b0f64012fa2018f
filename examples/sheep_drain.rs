//! Where a clip's simulated count and polarization part from the video's, frame by frame
//! (issue #46): runs the validation's simulation of the held-out frames `a..b` with a parameter
//! set through the clip's derived open boundary and prints, per frame and seed, the agents in
//! view, their mean vx, the polarization of the rasterised run beside the video's, and the agents
//! per grid column (what `validate` averages away).
//!
//! ```text
//! cargo run --release --example sheep_drain -- out/sheep-narrow/clip out/sheep-narrow/fitted.json 16 100 199
//! ```
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::ClipFields;
use herdfit::herd::boundary::gates_of_clip;
use herdfit::herd::guidance::guidance_fields;
use herdfit::herd::params::Params;
use herdfit::herd::validate::{simulate_clip, ValidateConfig};
use herdfit::measure::fields::emergent;
use std::path::Path;

fn main() -> herdfit::error::Result<()> {
    let a: Vec<String> = std::env::args().collect();
    if a.len() != 6 {
        eprintln!("usage: sheep_drain CLIP PARAMS.json SEEDS FIRST END");
        std::process::exit(2);
    }
    let clip = ClipFields::load(Path::new(&a[1]))?;
    let params = Params::load(Path::new(&a[2]))?;
    let num = |s: &str| -> usize {
        s.parse().unwrap_or_else(|_| {
            eprintln!("sheep_drain: {s} is not a count");
            std::process::exit(2)
        })
    };
    let (seeds, s0, s1) = (num(&a[3]), num(&a[4]), num(&a[5]));
    let cfg = ValidateConfig::default();
    let gates = gates_of_clip(&clip);
    let guidance = guidance_fields(&clip, cfg.guidance_scale);
    let device = cpu_device(Precision::F32)?;
    let g = clip.grid();
    println!("frame seed agents vx polarization video_polarization angular_momentum video_angular_momentum columns");
    for seed in 0..seeds as u64 {
        let run = simulate_clip(
            &clip,
            &params,
            s0..s1,
            seed,
            &cfg,
            None,
            &gates,
            &guidance,
            &device,
        )?;
        for (k, rows) in run.frames.iter().enumerate() {
            let n = rows.len();
            let vx = rows.iter().map(|r| r.vx).sum::<f64>() / n.max(1) as f64;
            let mut cols = vec![0usize; g.nx];
            for r in rows {
                let c = ((r.x - g.origin[0]) / g.cell_size).floor();
                cols[c.clamp(0.0, g.nx as f64 - 1.0) as usize] += 1;
            }
            let cs: Vec<String> = cols.iter().map(|c| c.to_string()).collect();
            let (sim, vid) = (
                emergent(&run.fields, k).values(),
                emergent(&clip, s0 + k).values(),
            );
            println!(
                "{} {seed} {n} {vx:.2} {:.4} {:.4} {:.4} {:.4} {}",
                s0 + k,
                sim[0],
                vid[0],
                sim[1],
                vid[1],
                cs.join(",")
            );
        }
        eprintln!("seed {seed}: {:?}", run.crossings);
    }
    Ok(())
}
