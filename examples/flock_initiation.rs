//! Initiation (Klotsman & Tal §6) from seeded random starts: the convergence rate behind
//! RESULTS.md §3, and a per-second trace of one run.
//!
//! `cargo run --release --example flock_initiation -- [N] [RUNS] [TRACE_SEED]`
//! (defaults 14, 100; with TRACE_SEED, one run's mean distance to the target over time).
//!
//! The target is the first key shape of the shipped 9-bird V (`examples/flocks/v.csv`) carried
//! to N birds (Algorithm 1 Step 1, seed N, brought into the example's shape family:
//! `animate::steady_setup`), as in `tests/flock.rs` and as `flock animate` does; start seeds are
//! 1000 + k, k < RUNS.

use herdfit::flock::extract::{self, ExtractConfig};
use herdfit::flock::initiation::{self, Initiation, InitiationConfig, Target};
use herdfit::flock::steady;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let n: usize = args.first().map_or(14, |a| a.parse().expect("N"));
    let runs: u64 = args.get(1).map_or(100, |a| a.parse().expect("RUNS"));
    let trace: Option<u64> = args.get(2).map(|a| a.parse().expect("TRACE_SEED"));
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let p = extract::extract_file(
        &root.join("examples/flocks/v.csv"),
        &ExtractConfig::default(),
    )
    .expect("examples/flocks/v.csv");
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    let setup =
        herdfit::flock::animate::steady_setup(&p, n, &steady::SteadyConfig::default(), &mut rng)
            .expect("initial shapes");
    let init = &setup.init;
    let target = Target {
        pos: setup.first.pos.clone(),
        nl: init.nl,
        nr: init.nr,
    };
    let cfg = InitiationConfig::default();
    let mut target_pair = f64::INFINITY;
    for (a, p) in target.pos.iter().enumerate() {
        for q in &target.pos[a + 1..] {
            target_pair = target_pair.min((p[0] - q[0]).hypot(p[1] - q[1]));
        }
    }
    if let Some(seed) = trace {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let start = initiation::random_start(n, &cfg, &mut rng);
        let mut sim = Initiation::new(cfg.clone(), target.clone(), start).expect("initiation");
        let steps = (cfg.max_time * cfg.fps) as usize;
        for s in 1..=steps {
            let d = sim.step();
            if s % cfg.fps as usize == 0 {
                let slotted = d.slots.iter().filter(|x| x.is_some()).count();
                let mut seen = vec![0usize; n];
                for t in d.slots.iter().flatten() {
                    seen[*t] += 1;
                }
                let dup = seen.iter().filter(|&&c| c > 1).count();
                let per: Vec<String> = (0..n)
                    .map(|i| match d.slots[i] {
                        Some(t) => {
                            let l = sim.birds[d.leader].pos;
                            let w = [
                                l[0] + target.pos[t][0] - target.pos[0][0],
                                l[1] + target.pos[t][1] - target.pos[0][1],
                            ];
                            let b = sim.birds[i].pos;
                            format!("{:.1}", (b[0] - w[0]).hypot(b[1] - w[1]))
                        }
                        None => "-".into(),
                    })
                    .collect();
                if std::env::var_os("FLOCK_DEBUG").is_some() {
                    for i in 0..n {
                        let b = sim.birds[i];
                        println!(
                            "  bird {i:>2} pos ({:>7.2}, {:>7.2}) θ {:>6.1}° v {:.3} ref {:?} side {:?} slot {:?}",
                            b.pos[0], b.pos[1], b.theta.to_degrees(), b.v, d.refs[i], d.sides[i], d.slots[i]
                        );
                    }
                }
                println!(
                    "t {:>4.0} s  mean {:>7}  slotted {slotted}/{n}  shared slots {dup}  per bird {}",
                    s as f64 / cfg.fps,
                    d.mean_error.map_or("-".into(), |e| format!("{e:.2}")),
                    per.join(" ")
                );
            }
        }
        return;
    }
    let out: Vec<_> = (0..runs)
        .into_par_iter()
        .map(|k| {
            let mut rng = ChaCha8Rng::seed_from_u64(1000 + k);
            let start = initiation::random_start(n, &cfg, &mut rng);
            initiation::run(Initiation::new(cfg.clone(), target.clone(), start).expect("init"))
        })
        .collect();
    let failed: Vec<String> = (0..runs)
        .filter(|&k| out[k as usize].converged_after.is_none())
        .map(|k| (1000 + k).to_string())
        .collect();
    if !failed.is_empty() {
        println!("not converged: seeds {}", failed.join(" "));
    }
    let ok: Vec<_> = out.iter().filter(|r| r.converged_after.is_some()).collect();
    let mut times: Vec<f64> = ok.iter().filter_map(|r| r.converged_after).collect();
    times.sort_by(f64::total_cmp);
    let pair = ok
        .iter()
        .map(|r| r.min_pair_distance)
        .fold(f64::INFINITY, f64::min);
    let fol = ok.iter().map(|r| r.max_followers).max().unwrap_or(0);
    println!(
        "N = {n}: {} of {runs} converged (mean distance ≤ {} b for {} s) within {} s; time median \
         {:.1} s, max {:.1} s; closest pair {pair:.2} b (in the target shape itself \
         {target_pair:.2} b); most followers of a non-leader {fol}",
        ok.len(),
        cfg.converge_distance,
        cfg.hold,
        cfg.max_time,
        times.get(times.len() / 2).copied().unwrap_or(f64::NAN),
        times.last().copied().unwrap_or(f64::NAN),
    );
}
