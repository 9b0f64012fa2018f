//! Fits from tracked animals (issue #49): a two-animal case whose optimum is known, the CLI's
//! `fit --objective tracks` and `validate-tracks` end to end, and bad tracks.

mod common;
use common::{fails, ok, s, small_clip};
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::agents::AgentRow;
use herdfit::herd::params::{param_names, Params, SpeedModel};
use herdfit::herd::sim::{
    theta_tensor, Decide, ForceKernel, ForceTensors, HerdState, Model, World,
};
use herdfit::herd::track_fit::{
    fit_tracks, mean_loss, Fix, Rollout, TrackClip, TrackFitConfig, TrackSet,
};
use rand::SeedableRng;
use std::path::Path;

/// Two animals 2 BL apart on converging headings, stepped by the model with `truth` (no speed
/// noise, no leaders, an open plane) for `frames` frames at 10 fps: their tracks, and the model.
fn pair(truth: &Params, frames: usize) -> TrackClip {
    let device = cpu_device(Precision::F32).unwrap();
    let model = Model {
        params: truth.clone(),
        world: World::open(),
        dt: 0.1,
        force_kernel: ForceKernel::Fused,
    };
    let (a, v) = (35f64.to_radians(), 1.5);
    let rows = vec![
        AgentRow {
            id: 0,
            x: 0.0,
            y: 0.0,
            vx: v * a.cos(),
            vy: v * a.sin(),
        },
        AgentRow {
            id: 1,
            x: 0.0,
            y: 2.0,
            vx: v * a.cos(),
            vy: -v * a.sin(),
        },
    ];
    let fixes = |pos: &[[f64; 2]]| -> Vec<Fix> {
        pos.iter()
            .enumerate()
            .map(|(i, &p)| Fix {
                id: i as u64,
                pos: p,
                vel: None,
            })
            .collect()
    };
    let mut out = vec![fixes(&[[rows[0].x, rows[0].y], [rows[1].x, rows[1].y]])];
    let theta = theta_tensor(&truth.to_vec(), &device);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let decide = Decide::Live {
        rng: &mut rng,
        record: None,
    };
    let state = HerdState::from_rows(&rows, &device);
    model
        .rollout(&theta, state, frames - 1, decide, |_, _, s| {
            out.push(fixes(&s.snapshot()?.pos));
            Ok(())
        })
        .unwrap();
    TrackClip {
        name: "pair".into(),
        tracks: TrackSet::new(10.0, out),
        model,
        guidance: Vec::new(),
        lookahead: 0,
        frames: 0..frames,
    }
}

/// Two animals made by the model itself without noise: the track objective is 0 at the set that
/// made them and positive away from it, and a fit of the two parameters that shape the pair's
/// approach (cohesion and alignment weights; the rest held) from 0.15 away ends at them.
#[test]
fn a_pair_made_by_the_model_is_fitted_back_to_its_parameters() {
    let truth = Params {
        speed: SpeedModel {
            mean: 1.5,
            std: 0.0,
            ..SpeedModel::default()
        },
        ..Params::default()
    };
    let clips = vec![pair(&truth, 60)];
    let names = param_names();
    let free = ["cohesion.weight", "alignment.weight"];
    for rollout in [Rollout::Conditioned, Rollout::Free] {
        let cfg = TrackFitConfig {
            rollout,
            horizon: 1.0,
            stride: 0.2,
            epochs: 30,
            lr: 0.01,
            learn_speed: false,
            frozen: names
                .iter()
                .filter(|n| !free.contains(&n.as_str()))
                .cloned()
                .collect(),
            ..TrackFitConfig::default()
        };
        let at_truth = mean_loss(&clips, &truth, &cfg).unwrap();
        assert!(at_truth < 1e-9, "{rollout}: {at_truth}");
        let mut v = truth.to_vec();
        v[0] += 0.15;
        v[6] -= 0.15;
        let start = truth.with_vec(&v);
        let away = mean_loss(&clips, &start, &cfg).unwrap();
        assert!(away > 1e-4, "{rollout}: {away}");
        let (fitted, log) = fit_tracks(&clips, &start, &cfg, |_, _, _| {}).unwrap();
        let (f, t) = (fitted.to_vec(), truth.to_vec());
        for (i, n) in names.iter().enumerate() {
            let tol = if free.contains(&n.as_str()) {
                0.02
            } else {
                0.0
            };
            assert!(
                (f[i] - t[i]).abs() <= tol,
                "{rollout}: {n} fitted {} truth {} (loss {} → {})",
                f[i],
                t[i],
                log[0].loss,
                log.last().unwrap().loss
            );
        }
    }
}

fn write(p: &Path, text: &str) {
    std::fs::write(p, text).unwrap();
}

/// Bad tracks get one line naming the file and write nothing, from `fit --objective tracks` and
/// from `validate-tracks`.
#[test]
fn bad_tracks_get_one_line_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let rows = |f: &dyn Fn(usize, usize) -> String| -> String {
        let mut t = String::from("frame,time,id,x,y\n");
        for k in 0..30 {
            for id in 0..3 {
                t.push_str(&f(k, id));
            }
        }
        t
    };
    let one = d.join("one.csv");
    let mut t = String::from("frame,time,id,x,y\n");
    for k in 0..30 {
        t.push_str(&format!("{k},{},7,{},1\n", k as f64 * 0.1, 0.1 * k as f64));
    }
    write(&one, &t);
    let nan = d.join("nan.csv");
    write(
        &nan,
        &rows(&|k, id| format!("{k},{},{id},nan,NaN\n", k as f64 * 0.1)),
    );
    let order = d.join("order.csv");
    let mut t = rows(&|k, id| format!("{k},{},{id},{},{id}\n", k as f64 * 0.1, 0.1 * k as f64));
    t.push_str("3,0.3,9,0,0\n");
    write(&order, &t);
    let params = d.join("p.json");
    Params::default().save(&params).unwrap();
    for (file, want) in [
        (&one, "one animal (id 7)"),
        (&nan, "every row (90) has a missing position"),
        (&order, "frame 3 after frame 29"),
    ] {
        let out = d.join("fitted.json");
        let e = fails(&[
            "fit",
            s(file),
            "--objective",
            "tracks",
            "--epochs",
            "1",
            "--out",
            s(&out),
        ]);
        assert!(e.contains(want) && e.contains(s(file)), "{e}");
        for p in ["fitted.json", "fitted.log.csv", "fitted.loss.png"] {
            assert!(!d.join(p).exists(), "{p} written after: {e}");
        }
        let report = d.join("report");
        let e = fails(&[
            "validate-tracks",
            s(file),
            "--params",
            s(&params),
            "--out",
            s(&report),
        ]);
        assert!(e.contains(want) && e.contains(s(file)), "{e}");
        assert!(!report.exists(), "{e}");
    }
    // The tracked animals enter and leave by themselves: the fields' open boundary is refused.
    let e = fails(&[
        "fit",
        s(&one),
        "--objective",
        "tracks",
        "--boundary",
        "closed",
        "--out",
        s(&d.join("fitted.json")),
    ]);
    assert!(
        e.contains("--boundary is an option of the fields objective"),
        "{e}"
    );
    assert!(!d.join("fitted.json").exists(), "{e}");
}

/// A small synthetic clip fitted from its trajectories and validated on them: the parameter set
/// records the objective, its learnt speed model and the identifiability estimate; the report
/// scores every set on the same windows and is the same bytes on a second run.
#[test]
fn fit_and_validate_from_a_clips_tracks() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = small_clip(d, 40, 30, 3);
    let out = d.join("p.json");
    let printed = ok(&[
        "fit",
        s(&clip),
        "--objective",
        "tracks",
        "--frames",
        "0..20",
        "--epochs",
        "2",
        "--horizon",
        "0.4",
        "--uncertainty-seeds",
        "2",
        "--out",
        s(&out),
    ]);
    assert!(
        printed.contains("track objective, conditioned rollout"),
        "{printed}"
    );
    let p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(p["provenance"]["objective"], "tracks");
    assert_eq!(p["provenance"]["frames"][0], serde_json::json!([0, 20]));
    assert!(
        p["uncertainty"]["std"]["cohesion.weight"].is_number()
            || p["uncertainty"]["bounds"]["cohesion.weight"].is_object()
    );
    assert!(p["speed"]["reversion"].as_f64().unwrap() > 0.0);
    assert!(d.join("p.log.csv").is_file() && d.join("p.loss.png").is_file());
    let run = |name: &str| {
        let r = d.join(name);
        ok(&[
            "validate-tracks",
            s(&clip),
            "--params",
            s(&out),
            "--frames",
            "20..30",
            "--horizons",
            "0.1,0.2",
            "--seeds",
            "3",
            "--free-run",
            "0.2",
            "--out",
            s(&r),
        ]);
        std::fs::read_to_string(r.join("report.json")).unwrap()
    };
    let (a, b) = (run("r1"), run("r2"));
    assert_eq!(a, b, "the same report twice");
    let r: serde_json::Value = serde_json::from_str(&a).unwrap();
    assert_eq!(r["schema"], "herdfit.track-eval/1");
    assert_eq!(r["speed_frames"][0], serde_json::json!([0, 20]));
    for ro in r["rollouts"].as_array().unwrap() {
        for h in ro["horizons"].as_array().unwrap() {
            assert!(h["samples"].as_u64().unwrap() > 0, "{h}");
            let sets = h["sets"].as_array().unwrap();
            assert_eq!(sets.len(), 3, "the set, generic and default");
            assert!(h["constant_velocity"][0].as_f64().unwrap() > 0.0);
        }
    }
    assert_eq!(r["rollouts"][0]["forecast"], false);
    assert_eq!(r["rollouts"][1]["forecast"], true);
}

/// Four animals walking abreast in +x at 1.5 BL/s, 3 BL apart, at 10 fps for 6 s, imported as a
/// clip (so the clip has a guidance field), and a set with every force weight 0.
fn walkers(d: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let mut t = String::from("frame,time,id,x,y\n");
    for k in 0..60 {
        for id in 0..4 {
            let x = 2.0 + 0.15 * k as f64;
            t.push_str(&format!("{k},{},{id},{x},{}\n", k as f64 * 0.1, 2 + 3 * id));
        }
    }
    let csv = d.join("walk.csv");
    write(&csv, &t);
    let clip = d.join("walk");
    ok(&["import-tracks", s(&csv), "--fps", "10", "--out", s(&clip)]);
    let mut v = Params::default().to_vec();
    for w in [0, 3, 6, 9] {
        v[w] = 0.0;
    }
    let zero = d.join("zero.json");
    Params::default().with_vec(&v).save(&zero).unwrap();
    (clip, zero)
}

/// `validate-tracks` of the walkers with `extra` flags: per rollout, per horizon, each set's ADE.
fn walker_ade(d: &Path, clip: &Path, zero: &Path, name: &str, extra: &[&str]) -> Vec<Vec<f64>> {
    let out = d.join(name);
    let mut args = vec![
        "validate-tracks",
        s(clip),
        "--params",
        s(zero),
        "--speeds",
        "expected",
        "--precision",
        "f64",
        "--seeds",
        "2",
        "--free-run",
        "0",
        "--out",
        s(&out),
    ];
    args.extend_from_slice(extra);
    ok(&args);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let mut ade = Vec::new();
    for ro in r["rollouts"].as_array().unwrap() {
        for h in ro["horizons"].as_array().unwrap() {
            assert!(h["samples"].as_u64().unwrap() >= 8, "{h}");
            let sets = h["sets"].as_array().unwrap();
            ade.push(sets.iter().map(|x| x["ade"].as_f64().unwrap()).collect());
        }
    }
    ade
}

/// The rollout starts from each animal's tracked position and velocity into the window's start
/// and steps at the clip's frame rate: a straight walker at constant speed with the forces off is
/// rolled out with zero error (1 s and 2 s, both rollouts), as constant velocity is.
#[test]
fn a_straight_walker_at_constant_speed_is_rolled_out_with_zero_error_when_the_forces_are_off() {
    let dir = tempfile::tempdir().unwrap();
    let (clip, zero) = walkers(dir.path());
    for ade in walker_ade(dir.path(), &clip, &zero, "r", &[]) {
        assert!(ade[0] < 1e-9, "zero-force ADE {ade:?}");
    }
}

/// Tracked groups are sparse: with the §5.1 leader rule every walker (no one in its front cone)
/// leads along the clip's guidance, so no force parameter can change a rollout (the real halves
/// of the fish and students003 had every set within 0.1 % of the others). The default,
/// `--leaders off`, lets the forces steer them: the default set's cohesion (radius 3.2 BL)
/// draws the walkers 3 BL apart together, the zero-force set walks straight.
#[test]
fn sparse_tracked_animals_are_steered_by_the_forces_not_the_leader_rule() {
    let dir = tempfile::tempdir().unwrap();
    let (clip, zero) = walkers(dir.path());
    let field = walker_ade(dir.path(), &clip, &zero, "field", &["--leaders", "field"]);
    let off = walker_ade(dir.path(), &clip, &zero, "off", &[]);
    for (f, o) in field.iter().zip(&off) {
        // The set, generic, default.
        assert!(
            (f[2] - f[0]).abs() < 1e-9,
            "leaders: the default set = the zero set {f:?}"
        );
        assert!(o[2] - o[0] > 0.1, "no leaders: the forces act {o:?}");
    }
}

/// Eq. 2, d' = N(v·d + Δt F), is undefined for an animal at rest with no force on it (a standing
/// pedestrian alone, or one whose force vanishes): it keeps its heading, on the plain device and
/// through autodiff alike, instead of a (near) zero heading that never moves again and whose
/// bearings gave the ETH/UCY track fit a non-finite gradient.
#[test]
fn an_animal_at_rest_with_no_force_on_it_keeps_its_heading() {
    use herdfit::herd::sim::{read_vec, Snapshot};
    let model = Model {
        params: Params::default(),
        world: World::open(),
        dt: 0.4,
        force_kernel: ForceKernel::Fused,
    };
    let still = Snapshot {
        pos: vec![[0.0, 0.0], [50.0, 0.0]],
        head: vec![[0.6, 0.8], [1.0, 0.0]],
        speed: vec![0.0, 1.0],
    };
    // f32: the precision the other tests of this process run in.
    let plain = cpu_device(Precision::F32).unwrap();
    for device in [plain.clone(), plain.autodiff()] {
        let theta = theta_tensor(&model.params.to_vec(), &device);
        let forces = ForceTensors::new(&theta, &model.params.constants);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut dec = model.decide(&still, &mut rng);
        dec.xi.iter_mut().for_each(|x| *x = 0.0);
        // No force, and a vanishing one (1e-20 BL/s², which N(u) would turn into a heading of
        // length 1e-14).
        let state = HerdState::from_snapshot(&still, &device);
        let tiny = model
            .step_with(&forces, &state, &dec, Some(&[[1e-20, 0.0], [0.0, 0.0]]))
            .unwrap();
        let th = (read_vec(&tiny.hx).unwrap(), read_vec(&tiny.hy).unwrap());
        assert_eq!(
            (th.0[0], th.1[0]),
            (0.6f32 as f64, 0.8f32 as f64),
            "vanishing force"
        );
        let next = model.step(&forces, &state, &dec).unwrap();
        let (hx, hy) = (read_vec(&next.hx).unwrap(), read_vec(&next.hy).unwrap());
        let f = |v: f64| v as f32 as f64;
        assert_eq!((hx[0], hy[0]), (f(0.6), f(0.8)), "at rest: its heading");
        assert!(
            (hx[1] - 1.0).abs() < 1e-6 && hy[1] == 0.0,
            "moving: unchanged"
        );
        let (x, y, v) = (
            read_vec(&next.x).unwrap(),
            read_vec(&next.y).unwrap(),
            read_vec(&next.speed).unwrap(),
        );
        assert!(v[0] > 0.0, "eq. 6 speeds it up towards v_μ");
        assert!((x[0] - 0.6 * v[0] * 0.4).abs() < 1e-6 && (y[0] - 0.8 * v[0] * 0.4).abs() < 1e-6);
    }
}

/// `--starts K`: K candidates (the given start first), each after a short fit scored by the
/// objective; the full fit starts from the lowest, and the set records them. Out of range: one
/// line naming the flag, nothing written.
#[test]
fn the_global_phase_starts_the_fit_from_the_lowest_of_its_candidates() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = small_clip(d, 30, 20, 4);
    let out = d.join("p.json");
    let fit = |starts: &str| {
        vec![
            "fit".to_string(),
            s(&clip).into(),
            "--objective".into(),
            "tracks".into(),
            "--horizon".into(),
            "0.3".into(),
            "--epochs".into(),
            "1".into(),
            "--start-epochs".into(),
            "1".into(),
            "--starts".into(),
            starts.into(),
            "--no-uncertainty".into(),
            "--out".into(),
            s(&out).into(),
        ]
    };
    let e = fails(&fit("0").iter().map(String::as_str).collect::<Vec<_>>());
    assert!(e.contains("--starts") && e.contains("out of range"), "{e}");
    assert!(!out.exists());
    let printed = ok(&fit("3").iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        printed.contains("global phase: 3 starts × 1 epochs"),
        "{printed}"
    );
    let p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let g = &p["provenance"]["global"];
    let c = g["candidates"].as_array().unwrap();
    assert_eq!(c.len(), 3);
    assert_eq!(
        c[0]["start"], p["provenance"]["start"],
        "the given start first"
    );
    let scores: Vec<f64> = c.iter().map(|x| x["score"].as_f64().unwrap()).collect();
    let best = g["best"].as_u64().unwrap() as usize;
    assert!(scores.iter().all(|&x| x >= scores[best]), "{scores:?}");
    assert!(c.iter().skip(1).all(|x| x["start"] != c[0]["start"]));
}
