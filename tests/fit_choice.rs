//! `fit --loss auto` (the default): the objective chosen on the fit's own frames
//! (`herd::fit::choose`). What a user relies on: the choice is scored by exactly what `validate`
//! reports on the second half, the chosen objective's fit is what a fit with that objective
//! gives, nothing is chosen where it cannot be (a still, too few frames), and the fitting
//! routines and the ablations refuse an unresolved `auto` by name.

mod common;
use common::{fails, fails_with, ok, s, small_clip};
use herdfit::herd::fit::{fit_clips, FitConfig, LossKind};
use herdfit::herd::params::Params;
use std::path::Path;

/// `fit CLIP --out OUT` with a short schedule, `choice_seeds` runs per candidate and `extra`.
fn fit_args<'a>(
    clip: &'a Path,
    out: &'a Path,
    choice_seeds: &'a str,
    extra: &[&'a str],
) -> Vec<&'a str> {
    let mut args = vec![
        "fit",
        s(clip),
        "--out",
        s(out),
        "--epochs",
        "2",
        "--window",
        "4",
        "--no-uncertainty",
        "--choice-seeds",
        choice_seeds,
        "--eval-seeds",
        "1",
    ];
    args.extend_from_slice(extra);
    args
}

/// [`fit_args`] with 3 choice seeds, run; returns the provenance.
fn fit(clip: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    ok(&fit_args(clip, out, "3", extra));
    Params::load(out).unwrap().provenance.unwrap()
}

fn values(p: &Path) -> Vec<f64> {
    Params::load(p).unwrap().to_vec().to_vec()
}

#[test]
fn auto_scores_each_objective_on_the_second_half_as_validate_does_and_fits_the_winner() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = small_clip(d, 90, 24, 5);
    let prov = fit(&clip, &d.join("auto.json"), &[]);
    let choice = &prov["loss_choice"];
    assert_eq!(
        choice["fit_frames"],
        serde_json::json!({"start": 0, "end": 12})
    );
    assert_eq!(
        choice["scored_frames"],
        serde_json::json!({"start": 12, "end": 24})
    );
    let cands = choice["candidates"].as_array().unwrap();
    assert_eq!(cands.len(), 2);
    assert_eq!(
        (cands[0]["loss"].as_str(), cands[1]["loss"].as_str()),
        (Some("fields"), Some("paper"))
    );
    let mean = |c: &serde_json::Value| {
        let v: Vec<f64> = c["scores"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(v.len(), 3, "one score per choice seed");
        v.iter().sum::<f64>() / 3.0
    };
    let chosen = choice["chosen"].as_str().unwrap();
    let want = if mean(&cands[1]) < mean(&cands[0]) {
        "paper"
    } else {
        "fields"
    };
    assert_eq!(chosen, want, "the lower mean score is chosen: {choice}");
    // The fitted set's settings name the chosen objective, and its values are those of a fit with
    // that objective given.
    assert_eq!(prov["settings"]["loss"], chosen);
    fit(&clip, &d.join("given.json"), &["--loss", chosen]);
    assert_eq!(values(&d.join("auto.json")), values(&d.join("given.json")));
    for (k, c) in cands.iter().enumerate() {
        // Each candidate is the fit with its objective on the first half …
        let cand = d.join(format!("cand{k}.json"));
        let loss = c["loss"].as_str().unwrap();
        fit(&clip, &cand, &["--loss", loss, "--frames", "0..12"]);
        let params: Vec<f64> = c["params"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect();
        assert_eq!(values(&cand), params, "{loss}");
        // … and its per-seed scores are validate's density + velocity errors on the second half.
        let rep = d.join(format!("val{k}"));
        ok(&[
            "validate",
            s(&clip),
            "--params",
            s(&cand),
            "--frames",
            "12..24",
            "--seeds",
            "3",
            "--no-video",
            "--out",
            s(&rep),
        ]);
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(rep.join("report.json")).unwrap())
                .unwrap();
        let seed_errors = r["sets"][0]["seed_errors"].as_array().unwrap();
        for (e, sc) in seed_errors.iter().zip(c["scores"].as_array().unwrap()) {
            let sum = e[0].as_f64().unwrap() + e[1].as_f64().unwrap();
            assert!(
                (sum - sc.as_f64().unwrap()).abs() < 1e-12,
                "{loss}: {sum} vs {sc}"
            );
        }
        assert!(c["density_error"].as_f64().unwrap() > 0.0);
    }
}

#[test]
fn nothing_is_chosen_where_the_frames_cannot_be_split() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = small_clip(d, 60, 7, 2);
    let prov = fit(&clip, &d.join("p.json"), &[]);
    assert_eq!(prov["loss_choice"]["chosen"], "fields");
    let why = prov["loss_choice"]["not_chosen"].as_str().unwrap();
    assert!(
        why.contains("7 frames") && why.contains("fewer than 10"),
        "{why}"
    );
    assert_eq!(prov["settings"]["loss"], "fields");
    // A given objective is not chosen for: no record.
    let prov = fit(&clip, &d.join("q.json"), &["--loss", "paper"]);
    assert!(prov.get("loss_choice").is_none(), "{prov}");
}

#[test]
fn the_fitting_routines_and_the_ablations_refuse_an_unresolved_auto() {
    let dir = tempfile::tempdir().unwrap();
    let clip = small_clip(dir.path(), 40, 10, 1);
    let c = herdfit::data::ClipFields::load(&clip).unwrap();
    let cfg = FitConfig {
        frames: 0..10,
        epochs: 1,
        loss: LossKind::Auto,
        ..FitConfig::default()
    };
    let e = fit_clips(&[&c], &Params::neutral(), &cfg, None, |_, _, _, _| {}).unwrap_err();
    assert!(
        e.to_string()
            .starts_with("loss: auto is chosen by a fit job"),
        "{e}"
    );
    // ablate and gradcheck take an objective, not the choice.
    for args in [
        &["ablate", s(&clip), "--loss", "auto"][..],
        &["gradcheck", "--loss", "auto"],
    ] {
        let err = fails_with(args, 2);
        assert!(
            err.contains("invalid value 'auto' for '--loss"),
            "{args:?}: {err}"
        );
    }
}

#[test]
fn a_resume_reuses_the_choice_and_refuses_one_made_with_other_seeds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = small_clip(d, 90, 24, 5);
    let ck = d.join("ck");
    fit(&clip, &d.join("a.json"), &["--checkpoint", s(&ck)]);
    assert!(ck.join("loss-choice.json").is_file());
    fit(
        &clip,
        &d.join("b.json"),
        &["--checkpoint", s(&ck), "--resume"],
    );
    assert_eq!(values(&d.join("a.json")), values(&d.join("b.json")));
    let c = d.join("c.json");
    let err = fails(&fit_args(
        &clip,
        &c,
        "5",
        &["--checkpoint", s(&ck), "--resume"],
    ));
    assert!(
        err.contains("loss-choice.json") && err.contains("other settings"),
        "{err}"
    );
    assert!(!c.exists(), "nothing written");
}
