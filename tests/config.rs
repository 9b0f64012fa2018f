//! Configs as the single source of truth (issue #13): library errors name config keys, the CLI
//! names its flags, a bad value read from a settings file names the file and the key, renamed
//! flags keep their old names, every report JSON carries a schema tag, and the library's fit job
//! writes what `herdfit fit` writes.

mod common;
use common::{fails, ok, s};
use herdfit::herd::fit::job::{run, FitJob};
use herdfit::herd::fit::{FitConfig, LossKind};
use herdfit::herd::simulate::SimulateConfig;
use herdfit::herd::validate::ValidateConfig;
use herdfit::progress::NoProgress;
use std::path::{Path, PathBuf};

/// `herdfit synth` into `dir/name` (10×6 cells of 3 BL), with the new flag names.
fn clip(dir: &Path, name: &str, agents: &str, frames: &str) -> PathBuf {
    let out = dir.join(name);
    ok(&[
        "synth",
        "--agents",
        agents,
        "--frame-count",
        frames,
        "--grid-size",
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
fn library_errors_name_config_keys_not_flags() {
    let lr = FitConfig {
        lr: 5.0,
        frames: 0..10,
        ..FitConfig::default()
    };
    assert_eq!(lr.check().unwrap_err().to_string(), "lr: 5 is out of range");
    let ensemble = FitConfig {
        loss: LossKind::Ensemble,
        frames: 0..10,
        ..FitConfig::default()
    };
    assert_eq!(
        ensemble.check().unwrap_err().to_string(),
        "replicas: loss ensemble compares several herds: set 2 or more"
    );
    let seeds = ValidateConfig {
        seeds: 0,
        ..ValidateConfig::default()
    };
    assert_eq!(seeds.check().unwrap_err().to_string(), "seeds: must be ≥ 1");
    let steps = SimulateConfig {
        steps: 0,
        ..SimulateConfig::default()
    };
    assert_eq!(steps.check().unwrap_err().to_string(), "steps: must be ≥ 1");
    let noise = SimulateConfig {
        speed_noise: Some(-1.0),
        ..SimulateConfig::default()
    };
    assert_eq!(
        noise.check().unwrap_err().to_string(),
        "speed_noise: -1 must be ≥ 0"
    );
    // The defaults are valid.
    assert!(ValidateConfig::default().check().is_ok());
    assert!(SimulateConfig::default().check().is_ok());
}

#[test]
fn the_cli_names_its_flags() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let c = clip(d, "clip", "40", "12");
    let out = d.join("p.json");
    let e = fails(&["fit", s(&c), "--out", s(&out), "--lr", "5"]);
    assert_eq!(e, "error: --lr: 5 is out of range");
    let e = fails(&["fit", s(&c), "--out", s(&out), "--loss", "ensemble"]);
    assert_eq!(
        e,
        "error: --replicas: --loss ensemble compares several herds: set 2 or more"
    );
    // A range judged against the clip names the clip too.
    let e = fails(&["fit", s(&c), "--out", s(&out), "--frames", "0..30"]);
    assert_eq!(
        e,
        format!(
            "error: {}: --frames: 0..30 is out of range: the clip has frames 0..12",
            c.display()
        )
    );
    let e = fails(&[
        "validate",
        s(&c),
        "--params",
        s(&c.join("truth.json")),
        "--coarse-grid",
        "0",
        "--out",
        s(&d.join("r")),
    ]);
    assert_eq!(e, "error: --coarse-grid: must be ≥ 1");
    let e = fails(&["simulate", "--steps", "3", "--out", s(&d.join("t.csv"))]);
    assert_eq!(
        e,
        "error: --init/--agents: give the initial herd: an INIT.csv file or a number of agents"
    );
    let e = fails(&[
        "synth",
        "--agents",
        "5",
        "--frame-count",
        "3",
        "--grid-size",
        "4x4",
        "--cell-size",
        "0",
        "--out",
        s(&d.join("x")),
    ]);
    assert_eq!(e, "error: --cell-size: 0 must be > 0");
    assert!(!out.exists() && !d.join("r").exists() && !d.join("x").exists());
}

#[test]
fn a_bad_value_from_a_settings_file_names_the_file_and_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let video = d.join("v.avi");
    ok(&[
        "synth",
        "--agents",
        "20",
        "--frame-count",
        "6",
        "--grid-size",
        "8x6",
        "--cell-size",
        "2",
        "--video-file",
        s(&video),
        "--out",
        s(&d.join("synth")),
    ]);
    let settings = d.join("extract.json");
    let out = d.join("clip");
    let extract = |extra: &[&str]| {
        let mut a = vec![
            "extract",
            s(&video),
            "--config",
            s(&settings),
            "--out",
            s(&out),
        ];
        a.extend_from_slice(extra);
        a.iter().map(|x| x.to_string()).collect::<Vec<_>>()
    };
    std::fs::write(&settings, r#"{"grid": 0, "body_length_px": 12}"#).unwrap();
    let v = extract(&[]);
    assert_eq!(
        fails(&args(&v)),
        format!("error: {}: grid: must be ≥ 1", settings.display())
    );
    // The same bad value given as a flag is named by the flag …
    let v = extract(&["--grid", "0"]);
    assert_eq!(fails(&args(&v)), "error: --grid: must be ≥ 1");
    // … and a flag that overrides the file's bad value is used.
    let v = extract(&["--grid", "8"]);
    ok(&args(&v));
    assert!(out.join("clip.json").is_file());
    std::fs::remove_dir_all(&out).unwrap();
    std::fs::write(&settings, r#"{"body_length_px": -1}"#).unwrap();
    let v = extract(&[]);
    assert_eq!(
        fails(&args(&v)),
        format!(
            "error: {}: body_length_px: -1 must be > 0",
            settings.display()
        )
    );
    // An unknown key is named by serde.
    std::fs::write(&settings, r#"{"gird": 8, "body_length_px": 12}"#).unwrap();
    let v = extract(&[]);
    let e = fails(&args(&v));
    assert!(
        e.contains(s(&settings)) && e.contains("unknown field `gird`"),
        "{e}"
    );
    assert!(!out.exists());
}

#[test]
fn renamed_flags_keep_their_old_names() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // synth: --frames / --grid / --video are --frame-count / --grid-size / --video-file.
    let synth = |name: &str, frames: &str, grid: &str, video: &str| {
        let out = d.join(name);
        ok(&[
            "synth",
            "--agents",
            "30",
            frames,
            "8",
            grid,
            "8x6",
            "--cell-size",
            "2",
            video,
            s(&d.join(format!("{name}.avi"))),
            "--out",
            s(&out),
        ]);
        out
    };
    let new = synth("new", "--frame-count", "--grid-size", "--video-file");
    let old = synth("old", "--frames", "--grid", "--video");
    for f in [
        "fields.npz",
        "truth.json",
        "trajectories.csv",
        "camera.json",
    ] {
        assert_eq!(
            std::fs::read(new.join(f)).unwrap(),
            std::fs::read(old.join(f)).unwrap(),
            "{f}"
        );
    }
    // fit: --init is --start.
    let start = new.join("truth.json");
    let fit = |out: &str, flag: &str| {
        let p = d.join(out);
        ok(&[
            "fit",
            s(&new),
            "--out",
            s(&p),
            flag,
            s(&start),
            "--epochs",
            "1",
            "--eval-seeds",
            "1",
        ]);
        std::fs::read(p).unwrap()
    };
    assert_eq!(fit("a.json", "--start"), fit("b.json", "--init"));
    // validate: --grid is --coarse-grid.
    let validate = |out: &str, flag: &str| {
        let r = d.join(out);
        ok(&[
            "validate",
            s(&new),
            "--params",
            s(&start),
            flag,
            "4",
            "--seeds",
            "1",
            "--no-video",
            "--out",
            s(&r),
        ]);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(r.join("report.json")).unwrap()).unwrap();
        assert_eq!(v["grid"], 4);
        std::fs::read(r.join("report.json")).unwrap()
    };
    assert_eq!(validate("r1", "--coarse-grid"), validate("r2", "--grid"));
}

/// The `schema` of the JSON file `p`.
fn schema(p: &Path) -> String {
    let v: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap();
    v["schema"].as_str().unwrap_or_default().to_string()
}

#[test]
fn every_report_json_carries_a_schema_tag() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let c = clip(d, "clip", "40", "10");
    let gc = d.join("gc.json");
    ok(&[
        "gradcheck",
        "--agents",
        "20",
        "--steps",
        "2",
        "--json",
        s(&gc),
    ]);
    assert_eq!(schema(&gc), "herdfit.gradcheck/1");
    let b = d.join("b.json");
    ok(&[
        "bench",
        "--agents",
        "20",
        "--steps",
        "2",
        "--sim-only",
        "--json",
        s(&b),
    ]);
    assert_eq!(schema(&b), "herdfit.bench/1");
    let r = d.join("r");
    ok(&[
        "validate",
        s(&c),
        "--params",
        s(&c.join("truth.json")),
        "--seeds",
        "1",
        "--no-video",
        "--out",
        s(&r),
    ]);
    assert_eq!(schema(&r.join("report.json")), "herdfit.validation/1");
    let info = d.join("info.json");
    ok(&["fields-info", s(&c), "--json", s(&info)]);
    assert_eq!(schema(&info), "herdfit.fields-info/1");
    // A scene shortened to one second.
    let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scenes.join("pasture.json")).unwrap())
            .unwrap();
    scene["duration"] = 1.0.into();
    let sp = d.join("pasture.json");
    std::fs::write(&sp, scene.to_string()).unwrap();
    std::fs::create_dir(d.join("pasture")).unwrap();
    for f in ["narrow.json", "broad.json"] {
        std::fs::copy(scenes.join("pasture").join(f), d.join("pasture").join(f)).unwrap();
    }
    let a = d.join("a");
    ok(&["author", s(&sp), "--out", s(&a)]);
    assert_eq!(schema(&a.join("report.json")), "herdfit.authoring/1");
    // The files that were tagged before stay tagged.
    assert_eq!(schema(&c.join("clip.json")), "herdfit.clip/1");
    assert_eq!(schema(&c.join("truth.json")), "herdfit.params/1");
}

#[test]
fn the_fit_job_writes_what_herdfit_fit_writes() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let c = clip(d, "clip", "60", "12");
    let cli = d.join("cli.json");
    ok(&[
        "fit",
        s(&c),
        "--out",
        s(&cli),
        "--window",
        "4",
        "--epochs",
        "2",
        "--loss",
        "fields",
        "--eval-seeds",
        "2",
    ]);
    let lib = d.join("lib.json");
    let job = FitJob {
        clips: vec![c.clone()],
        config: FitConfig {
            window: 4,
            epochs: 2,
            loss: LossKind::Fields,
            ..FitConfig::default()
        },
        eval_seeds: 2,
        out: lib.clone(),
        ..FitJob::default()
    };
    let summary = run(&job, &mut NoProgress).unwrap();
    assert_eq!(summary.windows_per_epoch, 3);
    assert_eq!(std::fs::read(&cli).unwrap(), std::fs::read(&lib).unwrap());
    assert_eq!(
        std::fs::read(d.join("cli.log.csv")).unwrap(),
        std::fs::read(d.join("lib.log.csv")).unwrap()
    );
    let p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&lib).unwrap()).unwrap();
    assert_eq!(p["provenance"]["source"], "fit");
    assert_eq!(p["provenance"]["evaluation"]["seeds"], 2);
    // Errors of a job name keys; the CLI's flags do not leak into the library.
    let bad = FitJob {
        eval_seeds: 0,
        ..job
    };
    assert_eq!(
        run(&bad, &mut NoProgress).unwrap_err().to_string(),
        "eval_seeds: 0 is out of range 1..=64"
    );
}

/// `v` as the `&str` arguments of [`fails`] and [`ok`].
fn args(v: &[String]) -> Vec<&str> {
    v.iter().map(String::as_str).collect()
}
