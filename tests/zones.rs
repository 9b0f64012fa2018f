//! Zones (issue #17, paper §7.2.4): the differentiable per-zone forces against the per-agent and
//! shared ones (fused and reference, f64), the zone fit's bundle and its use in an author scene,
//! and bad zones files.

mod common;
use burn::tensor::Tensor;
use common::{fails, ok, s};
use herdfit::backend::{cpu_device, Precision};
use herdfit::herd::params::Params;
use herdfit::herd::scenario::default_scenario;
use herdfit::herd::sim::{
    fused_forces, read_vec, thetas_tensor, ForceKernel, ForceTensors, HerdState, Model,
};
use rand::{Rng, SeedableRng};

fn sum_forces(
    m: &Model,
    f: &ForceTensors,
    s: &HerdState,
    dec: &herdfit::herd::sim::StepDecisions,
) -> Tensor<1> {
    let (fx, fy) = match m.force_kernel {
        ForceKernel::Fused => fused_forces(f, s, dec).expect("fused op"),
        _ => Model::reference_forces(f, s, dec),
    };
    // A weighted sum so that both components and every agent matter.
    let n = fx.dims()[0];
    let w: Vec<f64> = (0..n).map(|i| 1.0 + (i % 7) as f64 * 0.1).collect();
    let w =
        Tensor::<1>::from_data(burn::tensor::TensorData::new(w, [n]), &fx.device()).reshape([n, 1]);
    ((fx * w.clone()).sum() + (fy * w).sum().mul_scalar(0.5)).reshape([1])
}

#[test]
fn zoned_forces_equal_per_agent_ones_and_their_gradients_split_the_shared_gradient() {
    let dev = cpu_device(Precision::F64).unwrap();
    let ad = dev.clone().autodiff();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let a: [f64; 12] = std::array::from_fn(|_| rng.gen_range(0.2..0.9));
    let b: [f64; 12] = std::array::from_fn(|_| rng.gen_range(0.2..0.9));
    let sc = default_scenario(Params::default().with_vec(&a), 200, 3).unwrap();
    let c = sc.model.params.constants.clone();
    let zone: Vec<usize> = sc.init.iter().map(|r| usize::from(r.x > 0.0)).collect();
    assert!(zone.contains(&0) && zone.contains(&1));
    for kernel in [ForceKernel::Fused, ForceKernel::Reference] {
        let model = Model {
            force_kernel: kernel,
            ..sc.model.clone()
        };
        let state = HerdState::from_rows(&sc.init, &ad);
        let dec = model.decide(&state.snapshot().unwrap(), &mut rng.clone());
        // Values: zoned = per-agent with each agent's zone's set.
        let flat: Vec<f64> = a.iter().chain(&b).copied().collect();
        let th = thetas_tensor(&flat, &ad).require_grad();
        let zoned = ForceTensors::zoned(&th, &zone, &c);
        let thetas: Vec<[f64; 12]> = zone.iter().map(|&z| if z == 0 { a } else { b }).collect();
        let per = ForceTensors::per_agent(&thetas, &c, &ad);
        let lz = sum_forces(&model, &zoned, &state, &dec);
        let lp = sum_forces(&model, &per, &state, &dec);
        let (vz, vp) = (
            read_vec(&lz.clone().detach()).unwrap()[0],
            read_vec(&lp).unwrap()[0],
        );
        assert!(
            (vz - vp).abs() <= 1e-10 * (1.0 + vp.abs()),
            "{kernel:?}: {vz} vs {vp}"
        );
        // Gradients: with both zones at the same set a, zone 0's and zone 1's gradients add up
        // to the shared set's (each agent contributes through its own zone's copy), and each
        // part is non-zero.
        let same: Vec<f64> = a.iter().chain(&a).copied().collect();
        let th2 = thetas_tensor(&same, &ad).require_grad();
        let l2 = sum_forces(&model, &ForceTensors::zoned(&th2, &zone, &c), &state, &dec);
        let g2 = read_vec(&th2.grad(&l2.backward()).unwrap()).unwrap();
        let th1 = thetas_tensor(&a, &ad).require_grad();
        let l1 = sum_forces(&model, &ForceTensors::new(&th1, &c), &state, &dec);
        let g1 = read_vec(&th1.grad(&l1.backward()).unwrap()).unwrap();
        for p in 0..12 {
            let sum = g2[p] + g2[12 + p];
            assert!(
                (sum - g1[p]).abs() <= 1e-9 * (1.0 + g1[p].abs()),
                "{kernel:?} parameter {p}: {} + {} vs {}",
                g2[p],
                g2[12 + p],
                g1[p]
            );
        }
        assert!(g2[..12].iter().any(|v| v.abs() > 1e-8));
        assert!(g2[12..].iter().any(|v| v.abs() > 1e-8));
    }
}

/// The test's clip: 60 agents, 12 frames, seed 2 (`common::small_clip`).
fn small_clip(dir: &std::path::Path) -> std::path::PathBuf {
    common::small_clip(dir, 60, 12, 2)
}

fn zones_file(dir: &std::path::Path, name: &str, zones: serde_json::Value) -> std::path::PathBuf {
    let p = dir.join(name);
    let v = serde_json::json!({"schema": "herdfit.zones/1", "zones": zones});
    std::fs::write(&p, v.to_string()).unwrap();
    p
}

fn rect(x0: f64, x1: f64) -> serde_json::Value {
    serde_json::json!([[x0, 0.0], [x1, 0.0], [x1, 18.0], [x0, 18.0]])
}

/// The test's clip and zones "west" and "east", its two halves.
fn clip_and_halves(dir: &std::path::Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let zones = zones_file(
        dir,
        "zones.json",
        serde_json::json!([{"name": "west", "polygon": rect(0.0, 12.0)},
                           {"name": "east", "polygon": rect(12.0, 24.0)}]),
    );
    (small_clip(dir), zones)
}

#[test]
fn a_zone_fit_writes_a_bundle_that_an_author_scene_names_sets_of() {
    let dir = tempfile::tempdir().unwrap();
    let (clip, zones) = clip_and_halves(dir.path());
    let out = dir.path().join("sets.json");
    let printed = ok(&[
        "fit",
        s(&clip),
        "--zones",
        s(&zones),
        "--out",
        s(&out),
        "--epochs",
        "2",
        "--window",
        "3",
        "--eval-seeds",
        "1",
        "--loss",
        "fields",
    ]);
    assert!(printed.contains("fit --zones: 2 zones"), "{printed}");
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(b["schema"], "herdfit.param-sets/1");
    let sets = b["sets"].as_array().unwrap();
    assert_eq!(sets.len(), 2);
    assert_eq!(sets[0]["name"], "west");
    assert_eq!(sets[1]["params"]["schema"], "herdfit.params/1");
    // Both zones learnt: each set moved from the generic start, and differently.
    let vec = |k: usize| -> Vec<f64> {
        let p: Params = serde_json::from_value(sets[k]["params"].clone()).unwrap();
        p.to_vec().to_vec()
    };
    assert!(vec(0).iter().any(|v| (v - 0.5).abs() > 1e-6));
    assert!(vec(1).iter().any(|v| (v - 0.5).abs() > 1e-6));
    assert_ne!(vec(0), vec(1));
    // A bundle is validated in one run through the held-out part: a horizon is refused.
    let report = dir.path().join("report");
    let e = fails(&[
        "validate",
        s(&clip),
        "--params",
        s(&out),
        "--horizon",
        "5",
        "--out",
        s(&report),
    ]);
    assert!(e.contains("--horizon") && e.contains("zone bundle"), "{e}");
    assert!(!report.exists());
    // --ensemble-mean compares the seeds' mean emergent measures: with one seed that is the
    // seed's own; with three the emergent rows change and the density rows do not.
    let zone_rows = |seeds: &str, mean: bool| {
        let r = dir.path().join(format!("r{seeds}{mean}"));
        let mut args = vec![
            "validate",
            s(&clip),
            "--params",
            s(&out),
            "--seeds",
            seeds,
            "--no-video",
            "--out",
            s(&r),
        ];
        if mean {
            args.push("--ensemble-mean");
        }
        ok(&args);
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(r.join("report.json")).unwrap()).unwrap();
        assert_eq!(j["ensemble_mean"].as_bool().unwrap_or(false), mean);
        j["sets"][0]["zones"].clone()
    };
    assert_eq!(zone_rows("1", true), zone_rows("1", false));
    // From the tracked animals: the report names them, and the runs start elsewhere.
    let tracked = dir.path().join("rt");
    let tracks = clip.join("trajectories.csv");
    ok(&[
        "validate",
        s(&clip),
        "--params",
        s(&out),
        "--tracks",
        s(&tracks),
        "--no-video",
        "--out",
        s(&tracked),
    ]);
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tracked.join("report.json")).unwrap())
            .unwrap();
    assert_eq!(j["tracks"], s(&tracks));
    assert_ne!(j["sets"][0]["zones"], zone_rows("3", false));
    let (a, b) = (zone_rows("3", true), zone_rows("3", false));
    assert_eq!(a[0]["density_error"], b[0]["density_error"]);
    assert_ne!(a[0]["polarization_error"], b[0]["polarization_error"]);
    // An author scene's region names a set of the bundle.
    let scene = dir.path().join("scene.json");
    let v = serde_json::json!({
        "schema": "herdfit.scene/1",
        "world": {"width": 24, "height": 16, "cell_size": 2},
        "destination": {"point": [22, 8]},
        "regions": [{"polygon": [[12, 0], [24, 0], [24, 16], [12, 16]], "params": "sets.json", "set": "east"}],
        "spawn": {"count": 20, "centre": [6, 8], "size": [4, 4], "heading_deg": 0},
        "duration": 2, "fps": 10, "seed": 1
    });
    std::fs::write(&scene, v.to_string()).unwrap();
    ok(&[
        "author",
        s(&scene),
        "--out",
        s(&dir.path().join("authored")),
    ]);
    // A set the bundle does not hold is refused, naming the key.
    let bad = std::fs::read_to_string(&scene)
        .unwrap()
        .replace("\"east\"", "\"north\"");
    std::fs::write(&scene, bad).unwrap();
    let e = fails(&[
        "author",
        s(&scene),
        "--out",
        s(&dir.path().join("authored2")),
    ]);
    assert!(
        e.contains("regions[0].set") && e.contains("'north' is not in the bundle (west, east)"),
        "{e}"
    );
}

#[test]
fn a_zone_fit_with_a_global_phase_keeps_the_plain_zone_fit_as_candidate_0() {
    let dir = tempfile::tempdir().unwrap();
    let (clip, zones) = clip_and_halves(dir.path());
    let fit = |out: &std::path::Path, extra: &[&str]| -> String {
        let mut v = vec![
            "fit",
            s(&clip),
            "--zones",
            s(&zones),
            "--out",
            s(out),
            "--epochs",
            "2",
            "--window",
            "2",
            "--eval-seeds",
            "1",
            "--loss",
            "fields",
        ];
        v.extend_from_slice(extra);
        ok(&v)
    };
    let bundle = |p: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
    };
    let flat = |b: &serde_json::Value| -> Vec<f64> {
        let sets = b["sets"].as_array().unwrap();
        sets.iter()
            .flat_map(|x| {
                let p: Params = serde_json::from_value(x["params"].clone()).unwrap();
                p.to_vec().to_vec()
            })
            .collect()
    };
    let (g, plain) = (dir.path().join("g.json"), dir.path().join("plain.json"));
    let printed = fit(&g, &["--starts", "3"]);
    assert!(
        printed.contains("global phase: 3 starts refined on frames 0..9"),
        "{printed}"
    );
    let b = bundle(&g);
    let report = &b["provenance"]["global"];
    let cands = report["candidates"].as_array().unwrap();
    assert_eq!(cands.len(), 3);
    let vec = |x: &serde_json::Value| -> Vec<f64> {
        x.as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap())
            .collect()
    };
    // Every candidate starts every zone somewhere (12 values per zone); candidate 0 at the given start.
    assert!(cands.iter().all(|c| vec(&c["start"]).len() == 24));
    assert_eq!(vec(&cands[0]["start"]), vec![0.5; 24]);
    assert_ne!(vec(&cands[1]["start"]), vec(&cands[2]["start"]));
    // Candidate 0 is the plain zone fit on the refinement frames.
    fit(&plain, &["--frames", "0..9"]);
    assert_eq!(vec(&cands[0]["end"]), flat(&bundle(&plain)));
    // The bundle holds the chosen candidate's sets, the lowest held-out score.
    let chosen = report["chosen"].as_u64().unwrap() as usize;
    assert_eq!(flat(&b), vec(&cands[chosen]["end"]));
    let scores: Vec<f64> = cands.iter().map(|c| c["score"].as_f64().unwrap()).collect();
    assert!(scores.iter().all(|&x| x >= scores[chosen]), "{scores:?}");
}

#[test]
fn bad_zones_are_one_line_errors_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path());
    let out = dir.path().join("sets.json");
    let run = |z: &std::path::Path| {
        fails(&[
            "fit",
            s(&clip),
            "--zones",
            s(z),
            "--out",
            s(&out),
            "--epochs",
            "1",
            "--window",
            "3",
        ])
    };
    let overlap = zones_file(
        dir.path(),
        "overlap.json",
        serde_json::json!([{"name": "a", "polygon": rect(0.0, 15.0)},
                           {"name": "b", "polygon": rect(9.0, 24.0)}]),
    );
    let e = run(&overlap);
    assert!(
        e.contains("zones 'a' and 'b' overlap at cell (3, 0)"),
        "{e}"
    );
    let gap = zones_file(
        dir.path(),
        "gap.json",
        serde_json::json!([{"name": "a", "polygon": rect(0.0, 9.0)},
                           {"name": "b", "polygon": rect(12.0, 24.0)}]),
    );
    let e = run(&gap);
    assert!(
        e.contains("cell (3, 0), centre (10.500, 1.500), is in no zone"),
        "{e}"
    );
    // The herd starts upstream of the centre and never reaches the eastern strip in 12 frames.
    let empty = zones_file(
        dir.path(),
        "empty.json",
        serde_json::json!([{"name": "herd", "polygon": rect(0.0, 21.0)},
                           {"name": "far", "polygon": rect(21.0, 24.0)}]),
    );
    let e = run(&empty);
    assert!(
        e.contains("zone 'far' holds no agents in frames 0..12"),
        "{e}"
    );
    let twice = zones_file(
        dir.path(),
        "twice.json",
        serde_json::json!([{"name": "a", "polygon": rect(0.0, 12.0)},
                           {"name": "a", "polygon": rect(12.0, 24.0)}]),
    );
    assert!(run(&twice).contains("zones[1].name: 'a' is used twice"));
    assert!(!out.exists(), "a failed zone fit wrote {out:?}");
    let e = fails(&[
        "fit",
        s(&clip),
        s(&clip),
        "--zones",
        s(&twice),
        "--out",
        s(&out),
    ]);
    assert!(e.contains("--zones: a zone fit takes one clip"), "{e}");
    // A checkpoint of a fit of one set (or of other zones) is not resumed as a zone fit.
    let (ck, plain) = (dir.path().join("ck"), dir.path().join("plain.json"));
    let fit = |extra: &[&str]| -> Vec<String> {
        [
            "fit",
            s(&clip),
            "--epochs",
            "1",
            "--window",
            "3",
            "--checkpoint",
            s(&ck),
        ]
        .iter()
        .chain(extra)
        .map(|x| x.to_string())
        .collect()
    };
    let args = fit(&["--out", s(&plain)]);
    ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let halves = zones_file(
        dir.path(),
        "halves.json",
        serde_json::json!([{"name": "a", "polygon": rect(0.0, 6.0)},
                           {"name": "b", "polygon": rect(6.0, 24.0)}]),
    );
    let args = fit(&["--out", s(&out), "--zones", s(&halves), "--resume"]);
    let e = fails(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        e.contains("checkpoint.json: was written by a fit with other settings, another start or other zones"),
        "{e}"
    );
    assert!(!out.exists(), "a refused resume wrote {out:?}");
}
