//! `herdfit ablate` (paper §7.2): every switch applied to its variant, the report's files and
//! numbers, the `frozen` and `density_weight` fit keys, and bad input.

mod common;
use common::{fails, ok, s};
use herdfit::herd::fit::{fit, FitConfig, LossKind};
use herdfit::herd::params::Params;

/// The test's clip: 40 agents, 16 frames, seed 3 (`common::small_clip`).
fn small_clip(dir: &std::path::Path) -> std::path::PathBuf {
    common::small_clip(dir, 40, 16, 3)
}

#[test]
fn ablate_runs_every_switch_and_reports_table_4() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path());
    let out = dir.path().join("abl");
    let md = quick_ablate(&clip, &out, &[]);
    for f in [
        "ablation.json",
        "ablation.md",
        "density-error.png",
        "polarization.png",
        "errors.png",
        "params-full.json",
        "params-no-occlusion.json",
        "params-no-speed-density.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    assert_eq!(r["schema"], "herdfit.ablation/1");
    assert_eq!(r["fit_frames"], serde_json::json!([0, 8]));
    assert_eq!(r["heldout_frames"], serde_json::json!([8, 16]));
    let v = r["variants"].as_array().unwrap();
    let names: Vec<&str> = v.iter().map(|x| x["name"].as_str().unwrap()).collect();
    assert_eq!(
        names,
        [
            "full",
            "no-occlusion",
            "no-angular",
            "no-density",
            "no-dir-variance",
            "no-speed-density"
        ]
    );
    // The switches reached the fitted sets: occlusion off only in its variant; the angular
    // ranges held at 1 (Φ = π) through the fit.
    for (k, x) in v.iter().enumerate() {
        assert_eq!(x["occlusion"].as_bool().unwrap(), k != 1, "{}", names[k]);
        assert_eq!(x["rows"].as_array().unwrap().len(), 6);
    }
    for g in 0..4 {
        assert_eq!(v[2]["params"][3 * g + 2].as_f64().unwrap(), 1.0);
    }
    // The speed–density table is gone from its variant's speed model only.
    let speed = |name: &str| -> serde_json::Value {
        let p = std::fs::read_to_string(out.join(format!("params-{name}.json"))).unwrap();
        serde_json::from_str::<serde_json::Value>(&p).unwrap()["speed"].clone()
    };
    assert!(speed("full").get("density_table").is_some());
    assert!(speed("no-speed-density").get("density_table").is_none());
    // Table 4: the video's STD and every variant's error, as ablation.json holds them.
    assert!(md.contains("| measure | video STD | full model error | without occlusion error |"));
    let std = r["video"][2]["std"].as_f64().unwrap();
    assert!(md.contains(&format!("| polarization | {std:.4} |")), "{md}");
    for x in v {
        let e = x["rows"][0]["error"]["mean"].as_f64().unwrap();
        assert!(md.contains(&format!("{e:.4}")), "{e} not in the table");
    }
    assert!(md.contains("- **occlusion** helps"), "{md}");
}

#[test]
fn frozen_parameters_keep_their_start_and_bad_keys_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let clip = herdfit::data::ClipFields::load(&small_clip(dir.path())).unwrap();
    let start = Params::neutral();
    let cfg = FitConfig {
        frames: 0..8,
        epochs: 2,
        window: 3,
        loss: LossKind::Fields,
        density_weight: 0.5,
        frozen: vec!["cohesion.angular".into(), "alignment.weight".into()],
        ..FitConfig::default()
    };
    let r = fit(&clip, &start, &cfg, None, |_, _, _, _| {}).unwrap();
    let v = r.params.to_vec();
    assert_eq!(v[2], 0.5);
    assert_eq!(v[6], 0.5);
    assert!(v.iter().any(|x| *x != 0.5), "nothing moved: {v:?}");
    let bad = FitConfig {
        frozen: vec!["cohesion.colour".into()],
        ..cfg.clone()
    };
    let e = bad.check().unwrap_err().to_string();
    assert!(
        e.starts_with("frozen: 'cohesion.colour' is not a parameter"),
        "{e}"
    );
    let bad = FitConfig {
        density_weight: -1.0,
        ..cfg
    };
    let e = bad.check().unwrap_err().to_string();
    assert!(e.starts_with("density_weight: -1 is out of range"), "{e}");
}

#[test]
fn ablate_bad_input_is_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path());
    let out = dir.path().join("abl");
    let e = fails(&[
        "ablate",
        s(&clip),
        "--out",
        s(&out),
        "--switches",
        "occlusion,occlusion",
    ]);
    assert!(e.contains("switches: 'occlusion' is given twice"), "{e}");
    let e = fails(&["ablate", s(&clip), "--out", s(&out), "--switches", "wings"]);
    assert!(e.contains("--switches: 'wings' is not one of"), "{e}");
    let e = fails(&["ablate", s(&clip), "--out", s(&out), "--split", "0"]);
    assert!(e.contains("--split: 0 leaves no frames to fit"), "{e}");
    let e = fails(&["ablate", s(&clip), "--out", s(&out), "--window", "50"]);
    assert!(e.contains("--window"), "{e}");
    let e = fails(&["ablate", s(&dir.path().join("none")), "--out", s(&out)]);
    assert!(e.contains("none"), "{e}");
    assert!(!out.exists(), "a failed ablation left {out:?}");
}

/// `herdfit ablate CLIP --out OUT` with one 3-step epoch, one validation seed, no settling and
/// the `extra` flags: what it prints.
fn quick_ablate(clip: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> String {
    let mut v = vec![
        "ablate",
        s(clip),
        "--out",
        s(out),
        "--epochs",
        "1",
        "--window",
        "3",
        "--seeds",
        "1",
        "--settle",
        "0",
    ];
    v.extend_from_slice(extra);
    ok(&v)
}

/// Zones west (x < 6) and east of the test clip's 24 × 18 world.
fn two_zones(dir: &std::path::Path, split: f64) -> std::path::PathBuf {
    let rect = |a: f64, b: f64| serde_json::json!([[a, 0.0], [b, 0.0], [b, 18.0], [a, 18.0]]);
    let v = serde_json::json!({"schema": "herdfit.zones/1", "zones": [
        {"name": "west", "polygon": rect(0.0, split)},
        {"name": "east", "polygon": rect(split, 24.0)}]});
    let p = dir.join(format!("zones-{split}.json"));
    std::fs::write(&p, v.to_string()).unwrap();
    p
}

fn json(path: &std::path::Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn ablate_with_zones_fits_one_set_per_zone_in_every_variant_and_validates_each_zone() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path());
    let zones = two_zones(dir.path(), 6.0);
    let out = dir.path().join("abl");
    let md = quick_ablate(
        &clip,
        &out,
        &["--zones", s(&zones), "--switches", "occlusion,density"],
    );
    let r = json(&out.join("ablation.json"));
    assert_eq!(r["schema"], "herdfit.zone-ablation/1");
    assert_eq!(r["fit_frames"], serde_json::json!([0, 8]));
    assert_eq!(r["heldout_frames"], serde_json::json!([8, 16]));
    let v = r["variants"].as_array().unwrap();
    let names: Vec<&str> = v.iter().map(|x| x["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["full", "no-occlusion", "no-density"]);
    for (k, x) in v.iter().enumerate() {
        let sets = x["sets"].as_array().unwrap();
        let zones: Vec<&str> = sets.iter().map(|z| z["zone"].as_str().unwrap()).collect();
        assert_eq!(zones, ["west", "east"]);
        for z in sets {
            assert_eq!(z["occlusion"].as_bool().unwrap(), k != 1, "{}", names[k]);
        }
        // Each zone learnt its own set.
        assert_ne!(sets[0]["params"], sets[1]["params"]);
        let rows = x["validation"]["zones"].as_array().unwrap();
        assert_eq!(rows.len(), 2);
        for z in rows {
            let d = z["density_error"]["mean"].as_f64().unwrap();
            assert!(d.is_finite() && d > 0.0, "{z}");
        }
    }
    // The table: the whole grid's two errors and four per zone, every variant's value.
    for row in [
        "density error (whole grid)",
        "west: polarization error",
        "east: aspect ratio error",
    ] {
        assert!(md.contains(&format!("| {row} |")), "{row} missing: {md}");
    }
    let polar = v[1]["validation"]["zones"][1]["polarization_error"]["mean"]
        .as_f64()
        .unwrap();
    assert!(md.contains(&format!("{polar:.4}")), "{md}");
    assert!(
        md.contains("- **occlusion** helps (full model lower) on "),
        "{md}"
    );
    assert!(out.join("errors.png").is_file());
    // Each variant's bundle is what `validate --params` reads, and validating the full model's
    // bundle on the same held-out half reproduces the ablation's figures exactly.
    for n in &names {
        let b = json(&out.join(format!("params-{n}.json")));
        assert_eq!(b["schema"], "herdfit.param-sets/1");
        assert_eq!(b["sets"].as_array().unwrap().len(), 2);
    }
    let val = dir.path().join("val");
    ok(&[
        "validate",
        s(&clip),
        "--params",
        s(&out.join("params-full.json")),
        "--seeds",
        "1",
        "--settle",
        "0",
        "--no-video",
        "--out",
        s(&val),
    ]);
    let again = &json(&val.join("report.json"))["sets"][0];
    let full = &v[0]["validation"];
    for key in ["density_error", "velocity_error"] {
        assert_eq!(again[key]["mean"], full[key]["mean"], "{key}");
    }
    assert_eq!(again["zones"], full["zones"]);
}

#[test]
fn ablate_with_bad_zones_is_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path());
    let out = dir.path().join("abl");
    // The test clip's herd lies in the west: a zone from x = 12 holds none of it.
    let empty = two_zones(dir.path(), 12.0);
    let e = fails(&[
        "ablate",
        s(&clip),
        "--zones",
        s(&empty),
        "--out",
        s(&out),
        "--epochs",
        "1",
    ]);
    assert!(
        e.contains("zone 'east' holds no agents in frames 0..8: nothing to fit there"),
        "{e}"
    );
    let missing = dir.path().join("nope.json");
    let e = fails(&["ablate", s(&clip), "--zones", s(&missing), "--out", s(&out)]);
    assert!(e.contains("nope.json"), "{e}");
    assert!(!out.exists(), "a failed ablation left {out:?}");
}
