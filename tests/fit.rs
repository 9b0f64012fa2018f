//! The fit: loss terms and the target field on hand-made cases, a short fit that reduces the loss,
//! kill-and-resume identity, the loss gradient check, and bad input. Runs in f64.

mod common;
use common::{herdfit, ok, s};
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::{ClipFields, ClipMeta, ClipSpeed, Grid};
use herdfit::herd::fit::loss::{step_loss, StepTarget};
use herdfit::herd::fit::target::{splat_density, target_field, Stencil};
use herdfit::herd::params::Params;
use herdfit::herd::sim::read_vec;
use ndarray::{Array2, Array3, Array4};
use std::f64::consts::PI;
use std::path::Path;
use std::process::Command;

fn dev() -> burn::tensor::Device {
    cpu_device(Precision::F64).unwrap()
}

fn t1(v: Vec<f64>) -> burn::tensor::Tensor<1> {
    let n = v.len();
    burn::tensor::Tensor::from_data(burn::tensor::TensorData::new(v, [n]), &dev())
}

fn val(t: burn::tensor::Tensor<1>) -> f64 {
    read_vec(&t).unwrap()[0]
}

#[test]
fn e_mean_on_hand_made_agents() {
    // Three agents in cell 0 (target +x): a follower along +x, a follower along +y, a leader
    // along −x (excluded). E_mean = (0 + √2) / 2.
    let t = StepTarget {
        cell: vec![0, 0, 0],
        follower: vec![true, true, false],
        u: vec![[1.0, 0.0], [0.0, 0.0]],
        s: vec![0.0, 0.0],
        cell_mean: false,
    };
    let l = step_loss(&t1(vec![1.0, 0.0, -1.0]), &t1(vec![0.0, 1.0, 0.0]), &t);
    assert!((val(l.e_mean) - 2f64.sqrt() / 2.0).abs() < 1e-6);
    // An agent outside the grid or in a cell without target does not count.
    let t = StepTarget {
        cell: vec![0, -1, 1],
        follower: vec![true; 3],
        u: vec![[0.0, 1.0], [0.0, 0.0]],
        s: vec![0.0, 0.0],
        cell_mean: false,
    };
    let l = step_loss(&t1(vec![1.0, 1.0, 1.0]), &t1(vec![0.0, 0.0, 0.0]), &t);
    assert!((val(l.e_mean) - 2f64.sqrt()).abs() < 1e-6);
}

#[test]
fn e_var_on_hand_made_agents() {
    // Cell 0: two followers at ±30° around +x: variance (π/6)²; target S = 0.1.
    // Cell 1: a single follower (no variance term) — it still counts in the normalisation.
    let a = PI / 6.0;
    let t = StepTarget {
        cell: vec![0, 0, 1],
        follower: vec![true; 3],
        u: vec![[1.0, 0.0]; 2],
        s: vec![0.1, 0.5],
        cell_mean: false,
    };
    let l = step_loss(
        &t1(vec![a.cos(), a.cos(), 1.0]),
        &t1(vec![a.sin(), -a.sin(), 0.0]),
        &t,
    );
    let want = 2.0 * ((a * a) - 0.1f64).abs() / 3.0;
    let got = val(l.e_var);
    assert!((got - want).abs() < 1e-6, "{got} vs {want}");
    // Aligned agents matching S = 0 give zero.
    let t = StepTarget {
        cell: vec![0, 0],
        follower: vec![true; 2],
        u: vec![[1.0, 0.0]],
        s: vec![0.0],
        cell_mean: false,
    };
    let l = step_loss(&t1(vec![0.0, 0.0]), &t1(vec![1.0, 1.0]), &t);
    assert!(val(l.e_var) < 1e-5);
}

fn line_clip(density: [f32; 5], vel: [f32; 2]) -> ClipFields {
    let mut d = Array3::zeros((2, 1, 5));
    let mut v = Array4::zeros((2, 1, 5, 2));
    for f in 0..2 {
        for x in 0..5 {
            d[[f, 0, x]] = density[x];
            v[[f, 0, x, 0]] = vel[0];
            v[[f, 0, x, 1]] = vel[1];
        }
    }
    ClipFields {
        meta: ClipMeta::of_grid(
            &Grid {
                origin: [0.0, 0.0],
                cell_size: 1.0,
                nx: 5,
                ny: 1,
            },
            10.0,
            2,
            ClipSpeed {
                mean: 1.0,
                std: 0.1,
                density_table: vec![],
            },
        ),
        density: d,
        velocity: v,
        dir_variance: Array3::zeros((2, 1, 5)),
        obstacles: Array2::zeros((1, 5)),
    }
}

#[test]
fn target_field_points_up_the_missing_density() {
    // The clip has density only in cell 4; the simulation has nobody: D = −∇(ρ' − ρ) = ∇ρ points
    // towards cell 4 (+x) in cell 3. With β = 1, U = N(D) = +x there; with β = ½ and a clip
    // velocity +y, U = ½(1, 0) + ½(0, 1).
    let clip = line_clip([0.0, 0.0, 0.0, 0.0, 1.0], [0.0, 2.0]);
    let st = Stencil::new(&clip);
    let rho_sim = t1(vec![0.0; 5]);
    let rho = t1(vec![0.0, 0.0, 0.0, 0.0, 1.0]);
    let (vx, vy) = (t1(vec![0.0; 5]), t1(vec![2.0; 5]));
    let (ux, uy) = target_field(&rho_sim, &rho, &vx, &vy, &st, 1.0);
    let (ux, uy) = (read_vec(&ux).unwrap(), read_vec(&uy).unwrap());
    assert!((ux[3] - 1.0).abs() < 1e-9 && uy[3].abs() < 1e-9);
    // Cell 4 is a border cell: one-sided difference (ρ[4] − ρ[3]) also points +x.
    assert!((ux[4] - 1.0).abs() < 1e-9);
    // Far from the herd the density gradient vanishes: U is 0 there with β = 1.
    assert!(ux[0].abs() < 1e-6);
    let (ux, uy) = target_field(&rho_sim, &rho, &vx, &vy, &st, 0.5);
    let (ux, uy) = (read_vec(&ux).unwrap(), read_vec(&uy).unwrap());
    assert!((ux[3] - 0.5).abs() < 1e-9 && (uy[3] - 0.5).abs() < 1e-9);
}

/// An `nx × ny` grid of 2-BL cells at the origin.
fn grid2(nx: usize, ny: usize) -> Grid {
    Grid {
        origin: [0.0, 0.0],
        cell_size: 2.0,
        nx,
        ny,
    }
}

#[test]
fn splatting_is_bilinear_conserves_mass_and_is_differentiable() {
    let g = grid2(4, 3);
    // At a cell centre: all mass in that cell. Halfway between two centres: half and half.
    let pos = vec![[3.0, 3.0], [4.0, 1.0]];
    let rho = splat_density(&t1(vec![3.0, 4.0]), &t1(vec![3.0, 1.0]), &pos, &g);
    let r = read_vec(&rho).unwrap();
    assert!((r[4 + 1] - 0.25).abs() < 1e-12, "{r:?}");
    assert!(
        (r[1] - 0.125).abs() < 1e-12 && (r[2] - 0.125).abs() < 1e-12,
        "{r:?}"
    );
    assert!((r.iter().sum::<f64>() * 4.0 - 2.0).abs() < 1e-12);
    // d/dx of Σ w_c ρ_c against central differences.
    let w: Vec<f64> = (0..12).map(|k| (k as f64 * 0.7).sin()).collect();
    let j = |x: f64| -> f64 {
        let p = vec![[x, 2.6]];
        let r = read_vec(&splat_density(&t1(vec![x]), &t1(vec![2.6]), &p, &g)).unwrap();
        r.iter().zip(&w).map(|(a, b)| a * b).sum()
    };
    let ad = dev().autodiff();
    let x =
        burn::tensor::Tensor::<1>::from_data(burn::tensor::TensorData::new(vec![3.3], [1]), &ad)
            .require_grad();
    let y =
        burn::tensor::Tensor::<1>::from_data(burn::tensor::TensorData::new(vec![2.6], [1]), &ad);
    let wt =
        burn::tensor::Tensor::<1>::from_data(burn::tensor::TensorData::new(w.clone(), [12]), &ad);
    let s = (splat_density(&x, &y, &[[3.3, 2.6]], &g) * wt).sum();
    let gx = read_vec(&x.grad(&s.backward()).unwrap()).unwrap()[0];
    let fd = (j(3.3 + 1e-6) - j(3.3 - 1e-6)) / 2e-6;
    assert!((gx - fd).abs() < 1e-7, "{gx} vs {fd}");
}

#[test]
fn box_counts_blurred_like_splatting_match_the_mean_splat() {
    use herdfit::herd::fit::target::blur_like_splat;
    use rand::{Rng, SeedableRng};
    let g = grid2(5, 4);
    // 20 000 points uniform in cell (1, 2) and 20 000 in the corner cell (0, 0).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut pos = Vec::new();
    for (cx, cy) in [(1.0, 2.0), (0.0, 0.0)] {
        for _ in 0..20_000 {
            pos.push([(cx + rng.gen::<f64>()) * 2.0, (cy + rng.gen::<f64>()) * 2.0]);
        }
    }
    let x = t1(pos.iter().map(|p| p[0]).collect());
    let y = t1(pos.iter().map(|p| p[1]).collect());
    let splatted = read_vec(&splat_density(&x, &y, &pos, &g)).unwrap();
    // The same points binned into their cells, then blurred.
    let mut boxed = vec![0.0; 20];
    boxed[2 * 5 + 1] = 20_000.0 / 4.0;
    boxed[0] = 20_000.0 / 4.0;
    let blurred = blur_like_splat(&boxed, 5, 4);
    // ¾ · ¾ of a cell's mass stays, ¾ · ⅛ goes to each side neighbour; at the corner the
    // weights that leave the grid are lost, as splatting loses them.
    assert!((blurred[2 * 5 + 1] / boxed[2 * 5 + 1] - 0.5625).abs() < 1e-12);
    assert!((blurred[2 * 5 + 2] / boxed[2 * 5 + 1] - 0.09375).abs() < 1e-12);
    for c in 0..20 {
        assert!(
            (splatted[c] - blurred[c]).abs() < 0.02 * 5000.0,
            "cell {c}: splat {} vs blurred box {}",
            splatted[c],
            blurred[c]
        );
    }
    let total = |v: &[f64]| v.iter().sum::<f64>();
    assert!((total(&splatted) - total(&blurred)).abs() < 0.01 * total(&blurred));
}

fn make_clip(dir: &Path, name: &str, agents: &str, frames: &str) -> std::path::PathBuf {
    let out = dir.join(name);
    ok(&[
        "synth",
        "--agents",
        agents,
        "--frames",
        frames,
        "--grid",
        "10x6",
        "--cell-size",
        "3",
        "--seed",
        "3",
        "--out",
        s(&out),
    ]);
    out
}

#[test]
fn a_short_fit_reduces_the_loss() {
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path(), "clip", "120", "25");
    let out = dir.path().join("p.json");
    ok(&[
        "fit",
        s(&clip),
        "--out",
        s(&out),
        "--epochs",
        "4",
        "--window",
        "4",
        "--lr",
        "0.05",
        "--joint-gradients",
        // The paper's losses, whose sum this test follows (the default is field matching).
        "--loss",
        "paper",
    ]);
    let log = std::fs::read_to_string(dir.path().join("p.log.csv")).unwrap();
    let rows: Vec<Vec<f64>> = log
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
        .collect();
    let epoch_loss = |e: f64| -> f64 {
        let r: Vec<_> = rows.iter().filter(|r| r[0] == e).collect();
        r.iter().map(|r| r[2] + r[3]).sum::<f64>() / r.len() as f64 // e_mean + e_var
    };
    assert_eq!(rows.len(), 4 * 6, "4 epochs × 6 windows of 4 steps");
    assert!(epoch_loss(0.0) > 0.0);
    assert!(dir.path().join("p.loss.png").is_file());
    let p = Params::load(&out).unwrap();
    let prov = p.provenance.unwrap();
    // The same schedule (herd, noise) evaluated with the start and the fitted parameters.
    let l = &prov["loss"];
    let total = |k: &str| l[k]["e_mean"].as_f64().unwrap() + l[k]["e_var"].as_f64().unwrap();
    assert!(total("fitted") < total("start") - 0.005, "{l}");
    assert_eq!(prov["frames"], serde_json::json!([0, 25]));
    // The evaluation averages 4 runs by default; one run with the same seed is not that average.
    assert_eq!(prov["evaluation"]["seeds"], 4);
    assert!(prov["final_losses"]["e_mean"].as_f64().unwrap() > 0.0);
    // Stage 2: the speed model comes from the clip.
    let c = ClipFields::load(&clip).unwrap();
    assert_eq!(p.speed.mean, c.meta.speed.mean);
}

#[test]
fn a_field_matching_fit_reduces_its_loss() {
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path(), "clip", "120", "25");
    let out = dir.path().join("p.json");
    ok(&[
        "fit",
        s(&clip),
        "--out",
        s(&out),
        "--epochs",
        "4",
        "--window",
        "8",
        "--lr",
        "0.05",
        "--loss",
        "fields",
        "--seed",
        "2",
    ]);
    let p = Params::load(&out).unwrap();
    let l = &p.provenance.unwrap()["loss"];
    // The objective of --loss fields: E_fields + λ_var E_var (λ_var = 1).
    let f = |k: &str| l[k]["e_fields"].as_f64().unwrap() + l[k]["e_var"].as_f64().unwrap();
    assert!(f("fitted") < f("start") - 1e-3, "{l}");
    let log = std::fs::read_to_string(dir.path().join("p.log.csv")).unwrap();
    assert!(log.starts_with("epoch,frame,e_mean,e_var,e_fields,"));
    // (A bare fit chooses between fields and paper: tests/fit_choice.rs.)
}

#[test]
fn killed_and_resumed_fit_ends_with_the_same_bytes() {
    resume_case(&|_| vec!["--starts".into(), "1".into()], "checkpoint.json");
}

/// With the global phase: killed while the second candidate refines (its first checkpoint
/// written, the first candidate's complete), then resumed.
#[test]
fn killed_and_resumed_global_fit_ends_with_the_same_bytes() {
    resume_case(
        &|_| vec!["--starts".into(), "3".into()],
        "start-1/checkpoint.json",
    );
}

/// A zone fit (one set per zone, each with its own optimiser state in the checkpoint), alone and
/// with the global phase: killed after its first checkpoint and resumed, the bundle and the log
/// are the same bytes.
#[test]
fn killed_and_resumed_zone_fit_ends_with_the_same_bytes() {
    let zones = |d: &Path| -> Vec<String> {
        let rect = |a: f64, b: f64| serde_json::json!([[a, 0.0], [b, 0.0], [b, 18.0], [a, 18.0]]);
        let v = serde_json::json!({"schema": "herdfit.zones/1", "zones": [
            {"name": "west", "polygon": rect(0.0, 15.0)},
            {"name": "east", "polygon": rect(15.0, 30.0)}]});
        let p = d.join("zones.json");
        std::fs::write(&p, v.to_string()).unwrap();
        vec!["--zones".into(), s(&p).into()]
    };
    resume_case(&zones, "checkpoint.json");
    // With the global phase: killed while the second candidate refines.
    let global = |d: &Path| -> Vec<String> {
        let mut v = zones(d);
        v.extend(["--starts".to_string(), "3".to_string()]);
        v
    };
    resume_case(&global, "start-1/checkpoint.json");
}

/// A fit with the flags `extra(folder)` gives (it may write files into the test's folder), run
/// whole and run killed once `marker` (inside the checkpoint folder) exists and resumed: the
/// outputs are the same bytes.
fn resume_case(extra: &dyn Fn(&Path) -> Vec<String>, marker: &str) {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = make_clip(d, "clip", "200", "40");
    let extra = extra(d);
    let args = |out: &Path, ck: &Path| -> Vec<String> {
        [
            "fit",
            s(&clip),
            "--out",
            s(out),
            "--epochs",
            "12",
            "--window",
            "2",
            "--checkpoint",
            s(ck),
        ]
        .iter()
        .map(|x| x.to_string())
        .chain(extra.iter().cloned())
        .collect()
    };
    let (a, cka) = (d.join("a.json"), d.join("ck-a"));
    let v: Vec<String> = args(&a, &cka);
    ok(&v.iter().map(String::as_str).collect::<Vec<_>>());
    // Second run: kill it once its first checkpoint exists, then resume.
    let (b, ckb) = (d.join("b.json"), d.join("ck-b"));
    let v: Vec<String> = args(&b, &ckb);
    let mut child = Command::new(env!("CARGO_BIN_EXE_herdfit"))
        .args(&v)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    while !ckb.join(marker).exists() && t0.elapsed().as_secs() < 120 {
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    assert!(!b.exists(), "the run was killed before it finished");
    let mut v2 = v.clone();
    v2.push("--resume".into());
    ok(&v2.iter().map(String::as_str).collect::<Vec<_>>());
    for (x, y) in [
        (a.clone(), b.clone()),
        (d.join("a.log.csv"), d.join("b.log.csv")),
    ] {
        let (bx, by) = (std::fs::read(&x).unwrap(), std::fs::read(&y).unwrap());
        if x.extension().is_some_and(|e| e == "json") {
            // The clip path is the same; only the checkpoint folder differs, and it is not recorded.
            assert_eq!(bx, by, "{x:?} vs {y:?}");
        } else {
            assert_eq!(bx, by);
        }
    }
    // A resume with other settings is refused.
    // The checkpoints that were resumed, each candidate's (and the plain fit's) epochs complete.
    let written: Vec<_> = std::fs::read_dir(&ckb)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        written.iter().any(|n| marker.starts_with(n.as_str())),
        "{written:?}"
    );
    let mut v3 = args(&d.join("c.json"), &ckb);
    v3[5] = "8".into(); // --epochs 8
    v3.push("--resume".into());
    let o = herdfit(&v3.iter().map(String::as_str).collect::<Vec<_>>());
    assert_eq!(o.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&o.stderr).contains("other settings"));
}

#[test]
fn loss_gradcheck_passes() {
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path(), "clip", "120", "20");
    let json = dir.path().join("g.json");
    // The paper's loss, field matching, and the ensemble objective over 2 herds. The finite
    // differences use h = 1e-5: along avoidance.radial this clip's paper loss curves sharply
    // (a near-contact pair), and the 4-point formula at h = 1e-4 is off by 0.3 % there, while at
    // h = 1e-5 and 1e-6 it agrees with autodiff to 2e-8 (RESULTS.md §1).
    for (extra, bound) in [
        (&["--loss", "paper"][..], 1e-6),
        (&["--loss", "fields"][..], 1e-6),
        (&["--loss", "ensemble", "--replicas", "2"][..], 1e-6),
    ] {
        let mut args = vec![
            "gradcheck",
            "--objective",
            "loss",
            "--clip",
            s(&clip),
            "--steps",
            "8",
            "--fd-step",
            "1e-5",
            "--json",
            s(&json),
        ];
        args.extend_from_slice(extra);
        ok(&args);
        let g: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        assert!(
            g["max_rel_err"].as_f64().unwrap() <= bound,
            "{extra:?}: {g}"
        );
        assert_eq!(g["steps"], 8);
    }
}

#[test]
fn bad_fit_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = make_clip(d, "clip", "60", "10");
    let out = d.join("p.json");
    let fails = |args: &[&str], needle: &str| {
        let o = herdfit(args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        assert!(e.contains(needle), "{args:?}: {e}");
        assert!(!out.exists() && !d.join("p.log.csv").exists());
    };
    let bad = d.join("bad.json");
    std::fs::write(&bad, "{\"schema\": \"herdfit.params/1\"").unwrap();
    for (extra, needle) in [
        (&["--frames", "5..40"][..], "out of range"),
        (&["--frames", "5..6"][..], "at least 2 frames"),
        (&["--init", s(&bad)][..], "bad.json"),
        (&["--lr", "5"][..], "--lr"),
        (&["--loss", "ensemble"][..], "--replicas"),
        (&["--replicas", "0"][..], "--replicas"),
        (&["--guidance-scale", "-1"][..], "--guidance-scale"),
        (&["--guidance-scale", "NaN"][..], "--guidance-scale"),
        (&["--eval-seeds", "0"][..], "--eval-seeds"),
    ] {
        let mut args = vec!["fit", s(&clip), "--out", s(&out)];
        args.extend_from_slice(extra);
        fails(&args, needle);
    }
    fails(&["fit", s(&d.join("none")), "--out", s(&out)], "none");
    // A clip with zero density everywhere.
    let mut c = ClipFields::load(&clip).unwrap();
    c.density.fill(0.0);
    let empty = d.join("empty");
    c.save(&empty, &[]).unwrap();
    fails(&["fit", s(&empty), "--out", s(&out)], "zero everywhere");
    fails(
        &[
            "fit",
            s(&clip),
            "--out",
            s(&d.join("no-dir").join("p.json")),
        ],
        "no-dir",
    );
}

#[test]
fn gradient_checkpointing_gives_the_same_fit() {
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path(), "clip", "80", "20");
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let base = [
        "fit",
        s(&clip),
        "--window",
        "8",
        "--epochs",
        "2",
        "--loss",
        "fields",
    ];
    let mut x = base.to_vec();
    x.extend_from_slice(&["--out", s(&a)]);
    ok(&x);
    let mut y = base.to_vec();
    y.extend_from_slice(&["--out", s(&b), "--checkpointing"]);
    ok(&y);
    assert_eq!(
        Params::load(&a).unwrap().to_vec(),
        Params::load(&b).unwrap().to_vec()
    );
}

#[test]
fn ensemble_loss_subtracts_the_replicas_own_spread() {
    use herdfit::data::agents::AgentRow;
    use herdfit::herd::fit::target::blur_like_splat;
    use herdfit::herd::fit::{ensemble_loss, fields_loss};
    use herdfit::herd::sim::HerdState;
    // Clip frame 1: two agents' worth of density in cell 1, velocity +x everywhere.
    let mut clip = line_clip([0.0; 5], [1.0, 0.0]);
    clip.density[[1, 0, 1]] = 2.0;
    // Agents at cell centres splat wholly into their cell.
    let at = |cells: [usize; 2]| -> HerdState {
        let rows: Vec<AgentRow> = cells
            .iter()
            .enumerate()
            .map(|(i, &c)| AgentRow {
                id: i as u64,
                x: c as f64 + 0.5,
                y: 0.5,
                vx: 1.0,
                vy: 0.0,
            })
            .collect();
        HerdState::from_rows(&rows, &dev())
    };
    let (a, b) = (at([1, 1]), at([1, 3]));
    // The target is the clip's density blurred as splatting would see it; with speed 1 along +x
    // the momentum target is the same field, so both terms are equal.
    let target = blur_like_splat(&[0.0, 2.0, 0.0, 0.0, 0.0], 5, 1);
    let norm: f64 = target.iter().map(|t| t * t).sum();
    let plain = |rho: [f64; 5]| -> f64 {
        2.0 * rho
            .iter()
            .zip(&target)
            .map(|(r, t)| (r - t).powi(2))
            .sum::<f64>()
            / norm
    };
    let (la, lb) = (
        plain([0.0, 2.0, 0.0, 0.0, 0.0]),
        plain([0.0, 1.0, 0.0, 1.0, 0.0]),
    );
    assert!((val(fields_loss(&clip, &a, 1).unwrap()) - la).abs() < 1e-12);
    assert!((val(fields_loss(&clip, &b, 1).unwrap()) - lb).abs() < 1e-12);
    let e = |v: Vec<HerdState>| val(ensemble_loss(&clip, &v, 1).unwrap());
    // Identical replicas: no spread to subtract, the plain field loss.
    assert!((e(vec![a.clone(), a.clone()]) - la).abs() < 1e-12);
    assert!((e(vec![b.clone(), b.clone()]) - lb).abs() < 1e-12);
    // A and B: the mean of the two plain losses is ‖ρ̄ − ρ‖² + ‖ρ_A − ρ_B‖²/4 per term; the
    // estimate of ‖E ρ' − ρ‖² removes the replicas' spread, ‖ρ_A − ρ_B‖²/4 again, so it is lower
    // by ‖ρ_A − ρ_B‖²/2 = 1 per term (normalised): spread is not rewarded.
    let want = (la + lb) / 2.0 - 2.0 * 1.0 / norm;
    assert!((e(vec![a.clone(), b.clone()]) - want).abs() < 1e-12);
    // One replica is refused.
    assert!(ensemble_loss(&clip, &[a], 1).is_err());
}

#[test]
fn an_ensemble_fit_is_deterministic_and_logs_its_objective() {
    let dir = tempfile::tempdir().unwrap();
    let clip = make_clip(dir.path(), "clip", "80", "17");
    let run = |name: &str| {
        let out = dir.path().join(name);
        ok(&[
            "fit",
            s(&clip),
            "--out",
            s(&out),
            "--epochs",
            "2",
            "--window",
            "8",
            "--loss",
            "ensemble",
            "--replicas",
            "3",
            "--seed",
            "5",
        ]);
        (
            std::fs::read_to_string(&out).unwrap(),
            std::fs::read_to_string(dir.path().join(name.replace(".json", ".log.csv"))).unwrap(),
        )
    };
    let (p1, log1) = run("a.json");
    let (p2, log2) = run("b.json");
    // Same bytes apart from the output path in the recorded command.
    assert_eq!(p1.replace("a.json", "X"), p2.replace("b.json", "X"));
    assert_eq!(log1, log2);
    // The logged objective (e_fields column) is finite; the estimate of ‖E ρ' − ρ‖² may dip
    // below 0 only by its own noise, never by more than the plain loss.
    let rows: Vec<Vec<f64>> = log1
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(|x| x.parse().unwrap()).collect())
        .collect();
    assert_eq!(rows.len(), 2 * 2, "2 epochs of 2 windows");
    for r in &rows {
        assert!(r[4].is_finite() && r[4] > -1.0 && r[4] < 10.0, "{r:?}");
    }
    assert!(rows.iter().any(|r| r[4] != rows[0][4]));
}

#[test]
fn settling_keeps_cells_and_headings_and_separates_close_pairs() {
    use herdfit::herd::fit::{clip_model, init_herd, settle, Settle};
    use rand::SeedableRng;
    let dir = tempfile::tempdir().unwrap();
    let clip = ClipFields::load(&make_clip(dir.path(), "clip", "120", "3")).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
    let params = Params::default();
    let rows = init_herd(&clip, 0, &params.speed, &mut rng);
    let model = clip_model(params, &clip);
    let g = clip.grid();
    let settled = |n: usize| {
        let mut r = rows.clone();
        let cfg = Settle {
            iterations: n,
            ..Default::default()
        };
        settle(&model, &clip, &mut r, &cfg, &dev()).unwrap();
        r
    };
    // Agents whose nearest neighbour is closer than 0.4 BL.
    let crowded = |r: &[herdfit::data::agents::AgentRow]| {
        (0..r.len())
            .filter(|&i| {
                (0..r.len()).any(|j| {
                    j != i && ((r[i].x - r[j].x).powi(2) + (r[i].y - r[j].y).powi(2)).sqrt() < 0.4
                })
            })
            .count()
    };
    assert_eq!(settled(0), rows);
    let a = settled(200);
    assert_eq!(a, settled(200), "deterministic");
    for (p, q) in rows.iter().zip(&a) {
        assert_eq!(g.cell_of([p.x, p.y]), g.cell_of([q.x, q.y]));
        assert_eq!((p.vx, p.vy, p.id), (q.vx, q.vy, q.id));
    }
    let moved = rows
        .iter()
        .zip(&a)
        .filter(|(p, q)| (p.x - q.x).abs() + (p.y - q.y).abs() > 1e-6)
        .count();
    assert!(moved > rows.len() / 2, "{moved} of {} moved", rows.len());
    // Avoidance (0.8 BL range) pushes apart the near-coincident pairs uniform sampling makes.
    assert!(
        2 * crowded(&a) < crowded(&rows),
        "{} → {}",
        crowded(&rows),
        crowded(&a)
    );
}

#[test]
fn several_clips_are_fitted_jointly() {
    let dir = tempfile::tempdir().unwrap();
    let a = make_clip(dir.path(), "a", "80", "13");
    let b = dir.path().join("b");
    ok(&[
        "synth",
        "--agents",
        "60",
        "--frames",
        "9",
        "--grid",
        "10x6",
        "--cell-size",
        "3",
        "--seed",
        "8",
        "--out",
        s(&b),
    ]);
    let out = dir.path().join("p.json");
    ok(&[
        "fit",
        s(&a),
        s(&b),
        "--out",
        s(&out),
        "--epochs",
        "2",
        "--window",
        "4",
        "--seed",
        "1",
    ]);
    let p = Params::load(&out).unwrap();
    let prov = p.provenance.unwrap();
    assert_eq!(prov["clips"].as_array().unwrap().len(), 2);
    // The shortest clip sets the frames: 0..9, i.e. 2 windows of 4 steps per clip and epoch.
    assert_eq!(prov["frames"], serde_json::json!([0, 9]));
    let log = std::fs::read_to_string(dir.path().join("p.log.csv")).unwrap();
    assert!(log.lines().next().unwrap().ends_with(",clip"));
    let clips: Vec<&str> = log
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap())
        .collect();
    assert_eq!(clips, ["0", "0", "1", "1", "0", "0", "1", "1"]);
    // --frames beyond the shorter clip names it.
    let o = herdfit(&["fit", s(&a), s(&b), "--out", s(&out), "--frames", "0..12"]);
    assert_eq!(o.status.code(), Some(1));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains(s(&b)) && e.contains("out of range"), "{e}");
}

#[test]
fn the_clip_speed_model_reproduces_the_clip_speed_spread() {
    use herdfit::data::agents::AgentRow;
    use herdfit::herd::sim::{theta_tensor, ForceTensors, Guidance, HerdState, Model, World};
    use rand::SeedableRng;
    // A clip whose agents moved at 1.5 ± 0.2 BL/s (mean ± STD over agents and frames).
    let mut clip = line_clip([1.0; 5], [1.5, 0.0]);
    clip.meta.speed.mean = 1.5;
    clip.meta.speed.std = 0.2;
    let base = Params::default();
    let speed = herdfit::herd::params::SpeedModel::of_clip(&clip, &base.speed);
    // Eq. 6 with θ_OU = 1 settles to a spread of v_σ / √2: v_σ must be 0.2 · √2.
    assert!((speed.std - 0.2 * 2f64.sqrt()).abs() < 1e-12);
    assert!((speed.stationary_std() - 0.2).abs() < 1e-12);
    // Run the model's own speed update: 40 agents 10 BL apart (no neighbours), 60 s.
    let params = Params {
        speed,
        ..Default::default()
    };
    let model = Model {
        params: params.clone(),
        world: World {
            obstacles: None,
            guidance: Guidance::None,
            fixed_speed: None,
        },
        dt: 0.04,
        force_kernel: herdfit::herd::sim::ForceKernel::default(),
    };
    let rows: Vec<AgentRow> = (0..40)
        .map(|i| AgentRow {
            id: i,
            x: 10.0 * i as f64,
            y: 0.0,
            vx: 1.5,
            vy: 0.0,
        })
        .collect();
    let device = dev();
    let f = ForceTensors::new(&theta_tensor(&params.to_vec(), &device), &params.constants);
    let mut state = HerdState::from_rows(&rows, &device);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut samples = Vec::new();
    for t in 0..1500 {
        let dec = model.decide(&state.snapshot().unwrap(), &mut rng);
        state = model.step(&f, &state, &dec).unwrap();
        if t >= 100 {
            samples.extend(read_vec(&state.speed).unwrap());
        }
    }
    let n = samples.len() as f64;
    let m = samples.iter().sum::<f64>() / n;
    let sd = (samples.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n).sqrt();
    assert!((m - 1.5).abs() < 0.02, "mean {m}");
    assert!((sd - 0.2).abs() < 0.02, "spread {sd} (the clip's 0.2)");
}

/// A 5×3 clip of one frame: a herd moving +x whose top and bottom rows drift inwards (the flanks
/// of a contracting herd), cell (4, 1) empty, cell (0, 0) an obstacle.
fn flanked_clip() -> ClipFields {
    let mut c = line_clip([1.0; 5], [1.0, 0.0]);
    let (nx, ny) = (5, 3);
    c.meta.ny = ny;
    c.meta.frames = 1;
    c.density = Array3::from_elem((1, ny, nx), 1.0);
    c.velocity = Array4::zeros((1, ny, nx, 2));
    c.dir_variance = Array3::zeros((1, ny, nx));
    c.obstacles = Array2::zeros((ny, nx));
    for ix in 0..nx {
        c.velocity[[0, 0, ix, 0]] = 1.0;
        c.velocity[[0, 0, ix, 1]] = 0.5; // bottom row drifts up
        c.velocity[[0, 1, ix, 0]] = 1.0;
        c.velocity[[0, 2, ix, 0]] = 1.0;
        c.velocity[[0, 2, ix, 1]] = -0.5; // top row drifts down
    }
    c.density[[0, 1, 4]] = 0.0;
    c.velocity[[0, 1, 4, 0]] = 0.0;
    c.obstacles[[0, 0]] = 1;
    c.density[[0, 0, 0]] = 0.0;
    c
}

#[test]
fn leader_guidance_smooths_away_the_flanks_inward_drift() {
    use herdfit::herd::fit::guidance_field;
    use herdfit::herd::sim::{Guidance, World};
    let clip = flanked_clip();
    let at = |scale: f64, ix: usize, iy: usize| -> [f64; 2] {
        let g = guidance_field(&clip, 0, scale);
        assert!(matches!(g, Guidance::Field { .. }));
        let w = World {
            obstacles: None,
            guidance: g,
            fixed_speed: None,
        };
        w.guidance_at([ix as f64 + 0.5, iy as f64 + 0.5])
            .unwrap_or([0.0, 0.0])
    };
    // σ = 0: each cell's own direction; the empty cell takes its filled neighbours' mean (+x);
    // the obstacle cell gets none.
    let d = at(0.0, 2, 0);
    let n = (1.0f64 + 0.25).sqrt();
    assert!(
        (d[0] - 1.0 / n).abs() < 1e-9 && (d[1] - 0.5 / n).abs() < 1e-9,
        "{d:?}"
    );
    let e = at(0.0, 4, 1);
    assert!((e[0] - 1.0).abs() < 1e-9 && e[1].abs() < 1e-9, "{e:?}");
    assert_eq!(at(0.0, 0, 0), [0.0, 0.0]);
    // σ = ∞: the herd's mean direction everywhere accessible. The two flanks cancel except for
    // the obstacle's missing bottom-row cell: Σ m = (13, 4·0.5 − 5·0.5).
    let m = [13.0f64, -0.5];
    let l = (m[0] * m[0] + m[1] * m[1]).sqrt();
    for (ix, iy) in [(2, 0), (2, 2), (4, 1), (1, 1)] {
        let d = at(f64::INFINITY, ix, iy);
        assert!(
            (d[0] - m[0] / l).abs() < 1e-9 && (d[1] - m[1] / l).abs() < 1e-9,
            "{d:?}"
        );
    }
    assert_eq!(at(f64::INFINITY, 0, 0), [0.0, 0.0]);
    // σ = 1.5: in between, and the flanks' inward components shrink.
    let s = at(1.5, 2, 0);
    let raw = at(0.0, 2, 0);
    assert!(s[1] > 0.0 && s[1] < 0.5 * raw[1], "{s:?} vs {raw:?}");
    let t = at(1.5, 2, 2);
    assert!(t[1] < 0.0 && t[1] > 0.5 * at(0.0, 2, 2)[1], "{t:?}");
}

#[test]
fn the_averaged_step_follows_a_steady_gradient_and_damps_a_noisy_one() {
    use herdfit::herd::fit::{update, FitConfig, OptState, Optimizer};
    use rand::{Rng, SeedableRng};
    let cfg = |optimizer| FitConfig {
        optimizer,
        ..FitConfig::default()
    };
    // A steady gradient: every step moves lr along −g/‖g‖ (both running means bias-corrected),
    // exactly as the normalised step does.
    let g = [3.0, -4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0];
    for opt in [Optimizer::Averaged, Optimizer::Normalized] {
        let mut theta = [0.5; 12];
        let mut st = OptState::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
        for _ in 0..10 {
            update(&mut theta, &g, &mut st, &cfg(opt), 0.001, &mut rng);
        }
        assert!(
            (theta[0] - (0.5 - 10.0 * 0.001 * 0.6)).abs() < 1e-12,
            "{opt:?}: {theta:?}"
        );
        assert!(
            (theta[1] - (0.5 + 10.0 * 0.001 * 0.8)).abs() < 1e-12,
            "{opt:?}: {theta:?}"
        );
        assert!(theta[2..].iter().all(|&t| t == 0.5));
    }
    // Gradients that are pure noise about a minimum: the normalised step random-walks lr per
    // update, the averaged step's mean gradient averages out and it stays near the start.
    let walk = |opt| {
        let mut theta = [0.5; 12];
        let mut st = OptState::default();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
        let mut noise = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        for _ in 0..400 {
            let g: [f64; 12] = std::array::from_fn(|_| noise.gen::<f64>() - 0.5);
            update(&mut theta, &g, &mut st, &cfg(opt), 0.002, &mut rng);
        }
        theta.iter().map(|t| (t - 0.5).powi(2)).sum::<f64>().sqrt()
    };
    let (avg, norm) = (walk(Optimizer::Averaged), walk(Optimizer::Normalized));
    assert!(norm > 0.02, "normalised walk {norm}");
    assert!(avg < 0.3 * norm, "averaged {avg} vs normalised {norm}");
}
