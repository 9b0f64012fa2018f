//! The action model's continuation (`action.continuation`, ARCHITECTURE.md): an agent keeps
//! walking one real track's steps while the track's next sample is among its query's nearest,
//! and the learnt samples link each step to the next one of its own track.

mod common;

use common::{ok, s};
use herdfit::crowd::action::{
    ActionConfig, ActionModel, ActionOutput, ActionSamples, ClusterChoice, Scratch, NO_NEXT,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Samples in 2-D states: 0 at the origin (its track's next sample is 1), 1 and 2 side by side
/// at (1, 0) and (1, 0.01) with different steps, 3 and 4 far away.
fn model() -> ActionModel {
    ActionModel::new(ActionSamples {
        dims: 2,
        states: vec![0.0, 0.0, 1.0, 0.0, 1.0, 0.01, 5.0, 5.0, -5.0, 5.0],
        actions: vec![[0.5, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, -1.0], [-1.0, 0.0]],
        next: vec![1, NO_NEXT, NO_NEXT, NO_NEXT, NO_NEXT],
    })
    .unwrap()
}

fn config(continuation: usize) -> ActionConfig {
    ActionConfig {
        k: 3,
        clusters: 1,
        bandwidth_neighbour: 1,
        choice: ClusterChoice::Nearest,
        output: ActionOutput::Sample,
        continuation,
        ..ActionConfig::default()
    }
}

/// The steps output at `q` over 400 draws, after an agent whose last step was sample 0's.
fn steps_after_sample_0(
    m: &ActionModel,
    q: [f64; 2],
    cfg: &ActionConfig,
) -> BTreeMap<String, usize> {
    let mut sc = Scratch::default();
    // Sample 0's tree position: the one a decision at the origin reports with its step.
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let last = (0..100)
        .map(|_| m.decide(&[0.0, 0.0], [0.0, 0.0], cfg, &mut rng, &mut sc))
        .find(|d| d.action == [0.5, 0.0])
        .expect("sample 0 is drawn at its own state")
        .sample;
    assert_ne!(last, NO_NEXT, "a sampled output names its sample");
    let mut counts = BTreeMap::new();
    for _ in 0..400 {
        let d = m.decide_after(&q, [0.0, 0.0], last, cfg, &mut rng, &mut sc);
        *counts.entry(format!("{:?}", d.action)).or_insert(0) += 1;
    }
    counts
}

#[test]
fn continuation_takes_the_track_s_next_step_when_it_is_among_the_nearest() {
    let m = model();
    // Sample 1 (the track's next) is the nearest of 1 and 2 here.
    let q = [1.0, 0.004];
    let drawn = steps_after_sample_0(&m, q, &config(0));
    assert_eq!(
        drawn.len(),
        2,
        "without continuation both near steps are drawn: {drawn:?}"
    );
    assert!(drawn.values().all(|&n| n > 40), "{drawn:?}");
    let kept = steps_after_sample_0(&m, q, &config(1));
    assert_eq!(kept.len(), 1, "{kept:?}");
    assert_eq!(kept.get("[1.0, 0.0]"), Some(&400), "{kept:?}");
    // Nearer sample 2 than sample 1: with continuation 1 the track's next is not the nearest,
    // so the step is drawn; with 2 it is among the two nearest and taken.
    let q = [1.0, 0.008];
    let drawn = steps_after_sample_0(&m, q, &config(1));
    assert_eq!(drawn.len(), 2, "{drawn:?}");
    assert_eq!(
        steps_after_sample_0(&m, q, &config(2)).get("[1.0, 0.0]"),
        Some(&400)
    );
}

#[test]
fn samples_with_a_bad_next_index_are_refused() {
    let e = ActionModel::new(ActionSamples {
        dims: 2,
        states: vec![0.0, 0.0, 1.0, 0.0],
        actions: vec![[0.5, 0.0], [1.0, 0.0]],
        next: vec![2, NO_NEXT],
    })
    .err()
    .expect("index 2 of 2 samples is refused");
    assert!(e.to_string().contains("next"), "{e}");
}

/// A synthetic corridor crowd (`crowd synth`) in `dir`.
fn corridor(dir: &Path, seed: u64, secs: f64) -> PathBuf {
    let src = dir.join(format!("corridor-{seed}.csv"));
    ok(&[
        "crowd",
        "synth",
        "--seed",
        &seed.to_string(),
        "--duration",
        &secs.to_string(),
        "--out",
        s(&src),
    ]);
    src
}

/// `crowd learn SRC --preset pedestrians ARGS… --out DIR/NAME.json`, the model file read back.
fn learn(dir: &Path, src: &Path, name: &str, args: &[&str]) -> serde_json::Value {
    let out = dir.join(format!("{name}.json"));
    let mut all = vec!["crowd", "learn", s(src), "--preset", "pedestrians"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--out", s(&out)]);
    ok(&all);
    serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap()
}

/// [`learn`] with the settings file `json` laid over the preset.
fn learn_with(dir: &Path, src: &Path, name: &str, json: &str) -> serde_json::Value {
    let cfg = dir.join(format!("{name}.cfg.json"));
    std::fs::write(&cfg, json).unwrap();
    learn(dir, src, name, &["--config", s(&cfg)])
}

/// A corridor crowd learnt with continuation: each sample but the last of its track links to
/// the one a frame later in the same track; without continuation the model file has no links.
#[test]
fn learnt_samples_link_each_step_to_the_next_one_of_its_track() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = corridor(d, 2, 20.0);
    // Frames per individual (the synthetic corridor has no gaps).
    let mut frames: BTreeMap<String, usize> = BTreeMap::new();
    for line in std::fs::read_to_string(&src).unwrap().lines().skip(1) {
        *frames
            .entry(line.split(',').nth(2).unwrap().to_string())
            .or_default() += 1;
    }
    let with = learn_with(d, &src, "with", r#"{"action":{"continuation":1}}"#);
    let samples = &with["behaviours"][0]["samples"];
    let next: Vec<u64> = samples["next"]
        .as_array()
        .expect("next is written")
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    let n = samples["actions"].as_array().unwrap().len();
    // Every frame with a previous and a next one is a sample; all but each track's last link.
    let tracks = frames.values().filter(|&&f| f >= 3).count();
    let want_samples: usize = frames.values().filter(|&&f| f >= 3).map(|f| f - 2).sum();
    assert_eq!(n, want_samples, "one sample per inner frame");
    assert_eq!(next.len(), n);
    let links: Vec<(usize, usize)> = next
        .iter()
        .enumerate()
        .filter(|(_, &j)| j != NO_NEXT as u64)
        .map(|(i, &j)| (i, j as usize))
        .collect();
    assert_eq!(
        links.len(),
        n - tracks,
        "all but each track's last sample link"
    );
    assert!(
        links.iter().all(|&(i, j)| j == i + 1),
        "a track's samples are consecutive"
    );
    // Thinned to 400 of the samples (max_samples), in runs of consecutive steps: the kept
    // steps still link (evenly spaced single samples would keep almost no pair).
    let thinned = learn_with(
        d,
        &src,
        "thin",
        r#"{"action":{"continuation":1},"max_samples":400}"#,
    );
    let next = thinned["behaviours"][0]["samples"]["next"]
        .as_array()
        .unwrap();
    assert_eq!(next.len(), 400, "max_samples 400 of {n}");
    assert!(
        n >= 800,
        "the corridor gives {n} samples, enough for thinning to matter"
    );
    let kept = next
        .iter()
        .filter(|v| v.as_u64() != Some(NO_NEXT as u64))
        .count();
    // 50 runs of 8: 7 links each, less a run that straddles two tracks.
    assert!(kept >= 300, "{kept} of 400 thinned samples link");
    let without = learn_with(d, &src, "without", r#"{"action":{"continuation":0}}"#);
    assert!(
        without["behaviours"][0]["samples"].get("next").is_none(),
        "the model file is as before without continuation"
    );
}

/// `--continuation N` sets the key over any preset; a value out of range is named by its flag.
#[test]
fn the_continuation_flag_sets_the_key_and_its_errors_name_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let src = corridor(dir.path(), 4, 10.0);
    let m = learn(dir.path(), &src, "m", &["--continuation", "3"]);
    assert_eq!(m["config"]["action"]["continuation"], 3);
    let bad = dir.path().join("bad.json");
    let e = common::fails(&[
        "crowd",
        "learn",
        s(&src),
        "--continuation",
        "1000000",
        "--out",
        s(&bad),
    ]);
    assert!(
        e.contains("--continuation") && !e.contains("action."),
        "{e}"
    );
    assert!(!bad.exists(), "nothing written");
}
