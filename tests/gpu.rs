//! The GPU backend (cargo feature `gpu`, burn's wgpu backend) against the ndarray CPU backend:
//! forward steps, gradients through unrolled steps, a gradient check against finite differences
//! and a short fit, in f32 (issue #53). Run by CI on Mesa's lavapipe, a software Vulkan driver
//! (`scripts/setup-debian.sh` installs it; `CUBECL_WGPU_DEFAULT_DEVICE=Cpu` picks it): the GPU
//! path is exercised on a machine without a GPU. A machine without any Vulkan driver fails here
//! with the device's own message, not silently.
#![cfg(feature = "gpu")]

use burn::tensor::Device;
use herdfit::backend::{cpu_device, device, Compute, Precision};
use herdfit::herd::gradcheck::{autodiff_gradient, finite_difference_gradient, record, rel_err};
use herdfit::herd::params::Params;
use herdfit::herd::scenario::{default_scenario, Scenario};
use herdfit::herd::sim::{theta_tensor, Decide, ForceKernel, HerdState, Recording};
use rand::{Rng, SeedableRng};

/// The f32 tolerance of the parity checks, relative to 1 + |CPU value|: both backends compute in
/// f32 with the same operations, but the GPU's reductions and transcendental functions round
/// differently (a few ulps per step, growing through the unrolled steps: 1.9e-4 at worst over
/// the 20 steps of the seeds below, on lavapipe).
const F32_TOL: f64 = 1e-3;

fn gpu() -> Device {
    // Mesa's lavapipe when no hardware adapter is asked for: set once, before the runtime starts
    // and before any test thread reads the environment.
    static ENV: std::sync::Once = std::sync::Once::new();
    ENV.call_once(|| {
        if std::env::var_os("CUBECL_WGPU_DEFAULT_DEVICE").is_none() {
            std::env::set_var("CUBECL_WGPU_DEFAULT_DEVICE", "Cpu");
        }
        if std::env::var_os("XDG_RUNTIME_DIR").is_none() {
            std::env::set_var("XDG_RUNTIME_DIR", std::env::temp_dir());
        }
    });
    device(Compute::Gpu, Precision::F32).expect("the wgpu device (a Vulkan driver is installed)")
}

/// The tests that run the CubeCL force op in this process take turns: its pass counters
/// ([`herdfit::herd::sim::cube_op_passes`]) are per process, and a test that reads them must
/// see its own passes only.
fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

fn cpu() -> Device {
    cpu_device(Precision::F32).unwrap()
}

/// The gradcheck scene (obstacles inside the herd, uniform guidance so agents lead) with random
/// parameters, the forces computed by `kernel` on both devices (`Fused`: the ndarray op on the
/// CPU, the CubeCL op on the GPU; `Reference`: the tensor ops on both).
fn scene(agents: usize, seed: u64, kernel: ForceKernel) -> Scenario {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let theta: [f64; 12] = std::array::from_fn(|_| rng.gen_range(0.15..0.95));
    let mut sc = default_scenario(Params::default().with_vec(&theta), agents, seed).unwrap();
    sc.model.force_kernel = kernel;
    sc
}

const KERNELS: [ForceKernel; 2] = [ForceKernel::Fused, ForceKernel::Reference];

fn close(gpu: &[f64], cpu: &[f64], tol: f64, what: &str) -> f64 {
    assert_eq!(gpu.len(), cpu.len(), "{what}: lengths");
    let mut worst: f64 = 0.0;
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        assert!(g.is_finite(), "{what}[{i}]: GPU {g}");
        let e = (g - c).abs() / (1.0 + c.abs());
        assert!(
            e <= tol,
            "{what}[{i}]: GPU {g} vs CPU {c} (relative {e:.2e} > {tol:.0e})"
        );
        worst = worst.max(e);
    }
    worst
}

/// Positions and headings of `steps` replayed steps, every step.
fn trajectory(sc: &Scenario, rec: &Recording, steps: usize, dev: &Device) -> Vec<f64> {
    let theta = theta_tensor(&sc.model.params.to_vec(), dev);
    let mut out = Vec::new();
    sc.model
        .rollout::<rand_chacha::ChaCha8Rng>(
            &theta,
            HerdState::from_rows(&sc.init, dev),
            steps,
            Decide::Replay(rec),
            |_, _, s| {
                let snap = s.snapshot()?;
                out.extend(snap.pos.iter().chain(&snap.head).flatten());
                Ok(())
            },
        )
        .unwrap();
    out
}

#[test]
fn gpu_steps_follow_the_cpu_steps_within_f32_tolerance() {
    let _turn = one_at_a_time();
    let (g, c) = (gpu(), cpu());
    for (seed, kernel) in [1, 2].into_iter().flat_map(|s| KERNELS.map(|k| (s, k))) {
        let sc = scene(300, seed, kernel);
        let rec = record(&sc, 20, seed, &c).unwrap();
        let on_gpu = trajectory(&sc, &rec, 20, &g);
        let on_cpu = trajectory(&sc, &rec, 20, &c);
        // 300 agents × 4 values × 20 steps (frame 0 included where the rollout hands it over).
        assert!(on_cpu.len() >= 300 * 4 * 20, "{}", on_cpu.len());
        let worst = close(&on_gpu, &on_cpu, F32_TOL, "positions and headings");
        println!("seed {seed}, {kernel:?}: worst relative difference {worst:.2e}");
        // The herd moved: the last frame is not the first.
        let n = 300 * 4;
        let moved = on_cpu[..n]
            .iter()
            .zip(&on_cpu[on_cpu.len() - n..])
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(moved > 0.5, "the herd did not move: {moved}");
    }
}

#[test]
fn gpu_gradients_through_ten_steps_equal_the_cpu_gradients() {
    let _turn = one_at_a_time();
    let (g, c) = (gpu(), cpu());
    for (seed, kernel) in [11, 12].into_iter().flat_map(|s| KERNELS.map(|k| (s, k))) {
        let sc = scene(250, seed, kernel);
        let rec = record(&sc, 10, seed, &c).unwrap();
        let theta = sc.model.params.to_vec();
        let (jg, dg) = autodiff_gradient(&sc, &theta, &rec, 10, &g.clone().autodiff()).unwrap();
        let (jc, dc) = autodiff_gradient(&sc, &theta, &rec, 10, &c.clone().autodiff()).unwrap();
        close(&[jg], &[jc], F32_TOL, "J");
        // Gradients scale with J: tolerance relative to the largest component.
        let scale = dc.iter().map(|v| v.abs()).fold(0.0, f64::max);
        assert!(scale > 1e-6, "{dc:?}");
        let (dg, dc): (Vec<f64>, Vec<f64>) = dg
            .iter()
            .zip(&dc)
            .map(|(a, b)| (a / scale, b / scale))
            .unzip();
        let worst = close(&dg, &dc, 1e-3, "∂J/∂θ / max|∂J/∂θ|");
        println!(
            "seed {seed}, {kernel:?}: worst gradient difference {worst:.2e} of the largest component"
        );
    }
}

#[test]
fn gpu_autodiff_passes_the_gradient_check_against_cpu_finite_differences() {
    let _turn = one_at_a_time();
    let g = gpu();
    // Finite differences in f64 on the CPU are the truth; the GPU's f32 autodiff must meet them.
    // (f64 tensors need their own process: one precision per process on the CPU device, and the
    // finite differences here run in f32 with a step large enough for f32.)
    let c = cpu();
    // The default force kernel: the CubeCL op on the GPU.
    let sc = scene(120, 3, ForceKernel::Fused);
    let rec = record(&sc, 10, 3, &c).unwrap();
    let theta = sc.model.params.to_vec();
    let (_, ad) = autodiff_gradient(&sc, &theta, &rec, 10, &g.autodiff()).unwrap();
    let fd = finite_difference_gradient(&sc, &theta, &rec, 10, 1e-2, &c, || {}).unwrap();
    let scale = fd.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let mut worst: f64 = 0.0;
    for (p, (a, f)) in ad.iter().zip(&fd).enumerate() {
        let e = (a - f).abs() / scale;
        worst = worst.max(e);
        assert!(
            e <= 2e-2,
            "θ[{p}]: GPU autodiff {a} vs finite difference {f} ({e:.2e} of the largest, rel {:.2e})",
            rel_err(*a, *f)
        );
    }
    println!("gradcheck: GPU autodiff − finite differences at most {worst:.2e} of the largest");
}

mod common;
mod gpu_op;

/// A 2-epoch fit of the fields objective on a synthetic clip, once per device: the same
/// parameters within the f32 tolerance (the decisions are made live, on states that differ by
/// round-off).
#[test]
fn a_two_epoch_fit_on_the_gpu_ends_where_the_cpu_fit_ends() {
    let _turn = one_at_a_time();
    use herdfit::herd::fit::{fit, FitConfig, LossKind};
    gpu();
    let dir = tempfile::tempdir().unwrap();
    let clip = herdfit::data::ClipFields::load(&common::small_clip(dir.path(), 40, 16, 3)).unwrap();
    let start = Params::neutral();
    let on = |compute: Compute| {
        let cfg = FitConfig {
            frames: 0..12,
            epochs: 2,
            window: 4,
            loss: LossKind::Fields,
            device: compute,
            ..FitConfig::default()
        };
        fit(&clip, &start, &cfg, None, |_, _, _, _| {}).unwrap()
    };
    let before = herdfit::herd::sim::cube_op_passes();
    let g = on(Compute::Gpu);
    let after = herdfit::herd::sim::cube_op_passes();
    // The forces (forward and backward) went through the CubeCL op, not the tensor ops.
    assert!(
        after.0 > before.0 && after.1 > before.1,
        "the GPU fit ran no CubeCL force op: {before:?} → {after:?}"
    );
    let c = on(Compute::Cpu);
    let (pg, pc) = (g.params.to_vec(), c.params.to_vec());
    // The fit moved the parameters, by more than the tolerance.
    let moved = pc.iter().map(|v| (v - 0.5).abs()).fold(0.0, f64::max);
    assert!(moved > 1e-2, "the fit did not move: {pc:?}");
    for (p, (a, b)) in pg.iter().zip(&pc).enumerate() {
        assert!((a - b).abs() <= 1e-3, "θ[{p}]: GPU {a} vs CPU {b}");
    }
    let worst = pg
        .iter()
        .zip(&pc)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    println!("2-epoch fit: parameters moved up to {moved:.3}, GPU − CPU at most {worst:.2e}");
    assert_eq!(g.log.len(), c.log.len());
}

/// `herdfit simulate --device gpu` writes the trajectories the CPU run writes, within the f32
/// tolerance (decisions made live on each device), and the flags the GPU cannot honour are
/// refused in one line naming them.
#[test]
fn simulate_on_the_gpu_writes_the_cpu_trajectories_and_refuses_what_it_cannot_do() {
    use common::{fails, ok, s};
    gpu(); // the software adapter for the child processes too
    let dir = tempfile::tempdir().unwrap();
    let run = |device: &str| {
        let out = dir.path().join(format!("{device}.csv"));
        ok(&[
            "simulate",
            "--agents",
            "300",
            "--steps",
            "50",
            "--speed-noise",
            "0",
            "--device",
            device,
            "--out",
            s(&out),
        ]);
        let text = std::fs::read_to_string(out).unwrap();
        text.lines()
            .skip(1)
            .flat_map(|l| {
                let f: Vec<&str> = l.split(',').collect();
                [f[3].parse::<f64>().unwrap(), f[4].parse::<f64>().unwrap()]
            })
            .collect::<Vec<f64>>()
    };
    let (g, c) = (run("gpu"), run("cpu"));
    assert_eq!(c.len(), 51 * 300 * 2);
    close(&g, &c, F32_TOL, "simulated positions");
    let e = fails(&[
        "simulate",
        "--agents",
        "30",
        "--steps",
        "5",
        "--device",
        "gpu",
        "--precision",
        "f64",
        "--out",
        s(&dir.path().join("f64.csv")),
    ]);
    assert!(e.contains("--precision") && e.contains("f32"), "{e}");
    assert!(!dir.path().join("f64.csv").exists());
    let clip = common::small_clip(dir.path(), 40, 16, 3);
    let e = fails(&[
        "fit",
        s(&clip),
        "--objective",
        "tracks",
        "--device",
        "gpu",
        "--out",
        s(&dir.path().join("p.json")),
    ]);
    assert!(
        e.contains("--device gpu") && e.contains("fields objective"),
        "{e}"
    );
}

/// Every number of the CPU report `c` beside the GPU report `g` within [`F32_TOL`] (relative to
/// one plus the CPU value's magnitude), the same keys (the GPU's may add `device`), wall-clock
/// seconds skipped. Returns how many numbers were compared.
fn same_report(g: &serde_json::Value, c: &serde_json::Value, at: &str) -> usize {
    use serde_json::Value;
    match (g, c) {
        (Value::Object(g), Value::Object(c)) => {
            for k in g.keys() {
                assert!(
                    c.contains_key(k) || k == "device" || k == "force_op",
                    "{at}/{k}: only on the GPU"
                );
            }
            c.iter()
                .filter(|(k, _)| !k.ends_with("seconds") && !k.ends_with("_s"))
                .map(|(k, v)| {
                    let gv = g
                        .get(k)
                        .unwrap_or_else(|| panic!("{at}/{k}: missing on the GPU"));
                    same_report(gv, v, &format!("{at}/{k}"))
                })
                .sum()
        }
        (Value::Array(g), Value::Array(c)) => {
            assert_eq!(g.len(), c.len(), "{at}: lengths");
            let n = g.iter().zip(c).enumerate();
            n.map(|(i, (g, c))| same_report(g, c, &format!("{at}[{i}]")))
                .sum()
        }
        (Value::Number(g), Value::Number(c)) => {
            let (g, c) = (g.as_f64().unwrap(), c.as_f64().unwrap());
            close(&[g], &[c], F32_TOL, at);
            1
        }
        _ => {
            assert_eq!(g, c, "{at}");
            0
        }
    }
}

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Positions x, y of every row of a herdfit trajectories CSV (columns 3 and 4).
fn positions(path: &std::path::Path) -> Vec<f64> {
    let text = std::fs::read_to_string(path).unwrap();
    text.lines()
        .skip(1)
        .flat_map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            [f[3].parse::<f64>().unwrap(), f[4].parse::<f64>().unwrap()]
        })
        .collect()
}

/// `--device gpu` on every other verb that simulates the herd model (`synth`, `validate`,
/// `ablate`, `author`, `gradcheck`): each writes what its CPU run writes within the f32
/// tolerance, and its report says where it ran.
#[test]
fn every_verb_that_simulates_takes_device_gpu_and_writes_the_cpu_results() {
    use common::{ok, s};
    gpu(); // the software adapter for the child processes too
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = common::small_clip(d, 40, 16, 3);
    let out = |name: &str, device: &str| d.join(format!("{name}-{device}"));
    for device in ["cpu", "gpu"] {
        let synth = out("synth", device);
        let args = ["--grid-size", "8x6", "--cell-size", "3", "--seed", "3"];
        let mut a = vec!["synth", "--agents", "40", "--frame-count", "16"];
        a.extend(args);
        a.extend(["--device", device, "--out", s(&synth)]);
        ok(&a);
        let v = out("validate", device);
        let params = clip.join("truth.json");
        ok(&[
            "validate",
            s(&clip),
            "--params",
            s(&params),
            "--seeds",
            "2",
            "--no-video",
            "--device",
            device,
            "--out",
            s(&v),
        ]);
        let ab = out("ablate", device);
        ok(&[
            "ablate",
            s(&clip),
            "--switches",
            "occlusion",
            "--epochs",
            "1",
            "--seeds",
            "1",
            "--device",
            device,
            "--out",
            s(&ab),
        ]);
        let mut scene = json(std::path::Path::new("scenes/pasture.json"));
        scene["duration"] = serde_json::json!(1);
        let scene_path = d.join("pasture.json");
        // Its parameter sets resolve beside it.
        if !d.join("pasture").exists() {
            let sets = std::fs::canonicalize("scenes/pasture").unwrap();
            std::os::unix::fs::symlink(sets, d.join("pasture")).unwrap();
        }
        std::fs::write(&scene_path, scene.to_string()).unwrap();
        let a = out("author", device);
        ok(&["author", s(&scene_path), "--device", device, "--out", s(&a)]);
        if device == "gpu" {
            let gc = d.join("gradcheck.json");
            ok(&[
                "gradcheck",
                "--agents",
                "40",
                "--steps",
                "5",
                "--precision",
                "f32",
                "--device",
                "gpu",
                "--json",
                s(&gc),
            ]);
            let report = json(&gc);
            // The gradients went through the fused op's CubeCL kernels.
            assert_eq!(report["force_op"], "cubecl", "{report}");
            assert_eq!(report["device"], "gpu");
            let worst = report["max_rel_err"].as_f64().unwrap();
            println!("gradcheck --device gpu: max rel err {worst:.2e}");
            // The f32 tolerance of the library-level check above (the smallest gradient,
            // obstacle.weight ≈ 5e-4, carries the finite differences' f32 rounding).
            assert!(worst <= 2e-2, "gradcheck on the GPU: {worst}");
        }
    }
    let traj = |name: &str, device: &str| positions(&out(name, device).join("trajectories.csv"));
    for name in ["synth", "author"] {
        let (g, c) = (traj(name, "gpu"), traj(name, "cpu"));
        assert!(c.len() >= 2 * 40 * 16, "{name}: {} values", c.len());
        let worst = close(&g, &c, F32_TOL, name);
        // Another backend rounds differently somewhere: equal bytes would mean the flag was
        // ignored and both runs were the CPU's.
        assert!(
            worst > 0.0,
            "{name}: the GPU run equals the CPU run bit for bit"
        );
        println!("{name} --device gpu: positions within {worst:.2e} of the CPU run");
    }
    let report = |name: &str, file: &str, device: &str| json(&out(name, device).join(file));
    let (g, c) = (
        report("validate", "report.json", "gpu"),
        report("validate", "report.json", "cpu"),
    );
    assert_eq!(g["device"], "gpu", "the report says where it ran");
    assert_eq!(report("author", "report.json", "gpu")["device"], "gpu");
    let n = same_report(&g, &c, "validate");
    let (ga, ca) = (
        report("ablate", "ablation.json", "gpu"),
        report("ablate", "ablation.json", "cpu"),
    );
    let m = same_report(&ga, &ca, "ablate");
    assert!(
        n > 50 && m > 20,
        "numbers compared: validate {n}, ablate {m}"
    );
}
