//! The crowd system's alignment feature (`features.weights.alignment`, an extension of §4) and the
//! imitation of herdfit's own herd model that needs it (issue #20; `scripts/imitation.py` runs the
//! full protocol for RESULTS.md §4).

mod common;

use common::{ok, s};
use herdfit::crowd::features::{alignment, FeatureConfig, FeatureWeights, StateParts, SECTORS};
use std::path::{Path, PathBuf};

#[test]
fn alignment_sums_eq1_weighted_headings_in_the_agents_frame() {
    let r = 2.0;
    // Agent at the origin heading +y: "ahead" is +y, "left" is −x.
    let n = [
        ([1.0, 0.0], [1.0, 0.0]), // d = 1, heading +x (to the agent's right): f = 0.25
        ([0.0, 0.5], [0.0, 1.0]), // d = 0.5, heading like the agent: f = 0.5625
        ([3.0, 0.0], [-1.0, 0.0]), // d = 3 ≥ r: left out
        ([0.0, 0.0], [-1.0, 0.0]), // the agent's own position: left out
        ([-2.0, 0.0], [0.0, -1.0]), // d = r: f = 0, enters continuously
    ];
    let a = alignment([0.0, 0.0], [0.0, 1.0], n.into_iter(), r);
    assert!((a[0] - 0.5625).abs() < 1e-12, "ahead component {a:?}");
    assert!((a[1] + 0.25).abs() < 1e-12, "left component {a:?}");
}

#[test]
fn alignment_adds_two_state_values_only_when_weighted() {
    let parts = StateParts {
        speed: 1.0,
        now: [0.5; SECTORS],
        prev: [0.25; SECTORS],
        pivot: None,
        intent: [1.0, 0.0],
        align: Some([0.3, -0.4]),
    };
    let plain = FeatureWeights::default();
    let mut out = Vec::new();
    parts.write(&plain, &mut out);
    assert_eq!(out.len(), 19);
    assert_eq!(out.len(), FeatureConfig::dims(false, &plain));
    let w = FeatureWeights {
        alignment: 25.0,
        ..FeatureWeights::default()
    };
    let mut with = Vec::new();
    parts.write(&w, &mut with);
    assert_eq!(with.len(), FeatureConfig::dims(false, &w));
    assert_eq!(&with[..19], &out[..], "the other values are unchanged");
    assert_eq!(&with[19..], &[5.0 * 0.3, 5.0 * -0.4], "√25 × the alignment");
}

fn source(dir: &Path, seed: u64) -> PathBuf {
    let p = dir.join(format!("src{seed}.csv"));
    ok(&[
        "simulate",
        "--agents",
        "100",
        "--steps",
        "120",
        "--guidance",
        "1,0",
        "--seed",
        &seed.to_string(),
        "--out",
        s(&p),
    ]);
    p
}

/// W1 of speed, nearest neighbour, turning rate and polarization between two crowds.
fn compare(dir: &Path, a: &Path, b: &Path) -> [f64; 4] {
    let out = dir.join("compare.json");
    ok(&["crowd", "compare", s(a), s(b), "--json", s(&out)]);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let m = v["measures"].as_array().unwrap();
    let names = ["speed", "nearest_neighbour", "turning_rate", "polarization"];
    names.map(|n| {
        m.iter().find(|x| x["name"] == n).unwrap()["wasserstein"]
            .as_f64()
            .unwrap()
    })
}

/// Mean W1 of the imitations of sources `train`.. by a model learnt from sources ..`train` with
/// `config`.
fn imitate(dir: &Path, src: &[PathBuf], train: usize, config: &str) -> [f64; 4] {
    let cfg = dir.join("learn.json");
    std::fs::write(&cfg, config).unwrap();
    let model = dir.join("model.json");
    let mut args = vec!["crowd", "learn"];
    args.extend(src[..train].iter().map(|p| s(p)));
    args.extend(["--config", s(&cfg), "--out", s(&model)]);
    ok(&args);
    let mut sum = [0.0; 4];
    for (seed, target) in src.iter().enumerate().skip(train) {
        let out = dir.join("imitation.csv");
        ok(&[
            "crowd",
            "simulate",
            s(&model),
            "--entries",
            s(target),
            "--no-goals",
            "--seed",
            &seed.to_string(),
            "--out",
            s(&out),
        ]);
        let w = compare(dir, target, &out);
        (0..4).for_each(|i| sum[i] += w[i] / (src.len() - train) as f64);
    }
    sum
}

/// Sources 0–5 of the herd model and 2× their mean pairwise W1 (the run-to-run spread).
fn sources_and_limits(dir: &Path) -> (Vec<PathBuf>, [f64; 4]) {
    let src: Vec<PathBuf> = (0..6).map(|k| source(dir, k)).collect();
    let mut spread = [0.0; 4];
    let mut pairs = 0.0;
    for i in 0..src.len() {
        for j in i + 1..src.len() {
            let w = compare(dir, &src[i], &src[j]);
            (0..4).for_each(|m| spread[m] += w[m]);
            pairs += 1.0;
        }
    }
    (src, spread.map(|x| 2.0 * x / pairs))
}

/// The paper's Reynolds experiment on herdfit's herd model (sources 0–5: 15 source pairs, 5
/// imitations; model learnt from source 0 with k = 30). What holds on every set of sources
/// measured (RESULTS.md §4, seeds 0–8, 200–208, 300–308): speed and spacing within 2× the
/// sources' spread, and the alignment feature lowers the polarization error by at least a fifth.
/// (Turning rate and polarization are within 2× on sources 0–8 only; not asserted.)
#[test]
fn the_herd_imitation_keeps_speed_and_spacing_and_alignment_lowers_the_polarization_error() {
    let dir = tempfile::tempdir().unwrap();
    let (src, limit) = sources_and_limits(dir.path());
    let plain = imitate(dir.path(), &src, 1, r#"{"action":{"k":30}}"#);
    let aligned = imitate(
        dir.path(),
        &src,
        1,
        r#"{"action":{"k":30},"features":{"weights":{"alignment":100}}}"#,
    );
    for (m, name) in ["speed", "nearest neighbour"].iter().enumerate() {
        for (w, which) in [(plain[m], "k 30"), (aligned[m], "k 30 + alignment")] {
            assert!(
                w <= limit[m],
                "{name} ({which}): imitation W1 {w} vs 2× spread {}",
                limit[m]
            );
        }
    }
    assert!(
        aligned[3] < 0.8 * plain[3],
        "polarization W1 with alignment {} vs without {}",
        aligned[3],
        plain[3]
    );
}

/// Learnt from three sources (0–2) with k = 20 from the raw tracks (`smoothing` 0: a simulation
/// has no tracking noise), the imitations of sources 3–5 are within 2× the spread on all four
/// measures with the alignment feature, and out on polarization without it; §3's default
/// smoothing (σ = 1 frame) strips the sharp turns and raises the turning-rate error (RESULTS.md
/// §4: within on all five larger sets of sources with 36 imitations each; smoothed, two sets out
/// on turning).
#[test]
fn learnt_from_three_raw_sources_the_aligned_imitation_is_within_twice_the_spread() {
    let dir = tempfile::tempdir().unwrap();
    let (src, limit) = sources_and_limits(dir.path());
    let config = |smoothing: &str, alignment: &str| {
        format!(
            r#"{{"action":{{"k":20}},"max_samples":40000,"smoothing":{smoothing},"features":{{"weights":{{"alignment":{alignment}}}}}}}"#
        )
    };
    let aligned = imitate(dir.path(), &src, 3, &config("0", "100"));
    let plain = imitate(dir.path(), &src, 3, &config("0", "0"));
    let smoothed = imitate(dir.path(), &src, 3, &config("1", "100"));
    for (m, name) in ["speed", "nearest neighbour", "turning rate", "polarization"]
        .iter()
        .enumerate()
    {
        assert!(
            aligned[m] <= limit[m],
            "{name}: imitation W1 {} vs 2× spread {}",
            aligned[m],
            limit[m]
        );
    }
    assert!(
        plain[3] > limit[3],
        "without alignment the polarization W1 {} is within {}",
        plain[3],
        limit[3]
    );
    assert!(
        aligned[2] < 0.9 * smoothed[2],
        "turning-rate W1 from raw tracks {} vs smoothed {}",
        aligned[2],
        smoothed[2]
    );
}
