//! Where the whole-sequence lift spends its evaluations: per coarse-to-fine level, the energy
//! after 25, 50, 100, 200 … iterations, the evaluations, the time and the final depth error on a
//! synthetic boids flock seen by its ground observer (80° view, every point in view; the setting
//! of BENCHMARKS.md "Lift").
//!
//! `cargo run --release --example lift_levels -- BIRDS FRAMES ['{"sequence":{…}}' …]` — each JSON
//! argument is merged over the demo's lift settings (`LiftConfig` keys).

use herdfit::lift::boids::{synth_flock, BoidsConfig};
use herdfit::lift::frame::frame_by_frame;
use herdfit::lift::sequence::whole_sequence;
use herdfit::lift::{demo_config, LiftConfig, Observations};
use herdfit::progress::{NoProgress, Progress};
use std::time::Instant;

/// Records each level's energy after every iteration.
#[derive(Default)]
struct Trace {
    levels: Vec<(String, Vec<f64>)>,
}

impl Progress for Trace {
    fn start(&mut self, what: &str, _len: u64) {
        self.levels.push((what.to_string(), Vec::new()));
    }
    fn inc(&mut self, _n: u64) {}
    fn message(&mut self, msg: &str) {
        if let (Some(l), Some(v)) = (self.levels.last_mut(), msg.strip_prefix("E ")) {
            l.1.push(v.parse().unwrap_or(f64::NAN));
        }
    }
    fn finish(&mut self) {}
}

fn merge(base: &mut serde_json::Value, over: &serde_json::Value) {
    match (base, over) {
        (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
            for (k, v) in o {
                merge(b.entry(k.clone()).or_insert(serde_json::Value::Null), v);
            }
        }
        (b, o) => *b = o.clone(),
    }
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let birds: usize = a.get(1).map_or(200, |s| s.parse().unwrap());
    let frames: usize = a.get(2).map_or(200, |s| s.parse().unwrap());
    let mut b = BoidsConfig::default();
    (b.birds, b.frames, b.crop, b.hfov) = (birds, frames, false, 80.0);
    let syn = synth_flock(&b, &mut NoProgress).unwrap();
    let obs = Observations::new(&syn.tracks, &syn.camera).unwrap();
    let overrides: Vec<String> = if a.len() > 3 {
        a[3..].to_vec()
    } else {
        vec!["{}".into()]
    };
    let t0 = Instant::now();
    let base = demo_config(&b);
    let fbf = frame_by_frame(&obs, &base, &mut NoProgress).unwrap();
    println!(
        "{birds} birds × {frames} frames: {} points, frame by frame {:.2} s",
        obs.len(),
        t0.elapsed().as_secs_f64()
    );
    let mean = syn.depth.iter().sum::<f64>() / syn.depth.len() as f64;
    for o in &overrides {
        let mut v = serde_json::to_value(&base).unwrap();
        merge(&mut v, &serde_json::from_str(o).unwrap());
        let cfg: LiftConfig = serde_json::from_value(v).unwrap();
        let mut trace = Trace::default();
        let t = Instant::now();
        let (d, log) = whole_sequence(&obs, &fbf, &cfg, &mut trace).unwrap();
        let secs = t.elapsed().as_secs_f64();
        let rmse = (d
            .iter()
            .zip(&syn.depth)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            / d.len() as f64)
            .sqrt();
        println!(
            "{o}: {secs:.2} s, {} evaluations, iterations {:?}, E {:.6} → {:.6}, depth RMSE {:.3} m ({:.2}%)",
            log.evaluations,
            log.iterations,
            log.start.total,
            log.end.total,
            rmse,
            100.0 * rmse / mean
        );
        for (name, e) in &trace.levels {
            let at: Vec<String> = [1usize, 10, 25, 50, 100, 150, 200, 300, 500, 1000]
                .iter()
                .filter(|&&k| k <= e.len())
                .map(|&k| format!("{k}:{:.6}", e[k - 1]))
                .collect();
            println!("  {name}: {}", at.join(" "));
        }
    }
}
