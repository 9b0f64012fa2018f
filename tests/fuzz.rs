//! Property-based fuzzing of every file parser (issue #14): for each, `HERDFIT_FUZZ_CASES`
//! (default 10,000) cases of arbitrary bytes and structured mutations of a valid file (see
//! `fuzz/engine.rs`) must give `Ok` (with finite values where the parser promises them) or an
//! error naming the file — never a panic, never more heap than the memory limit allows. Seeds are
//! fixed, so a failure reproduces; proptest shrinks it to a small case.
//!
//! Longer runs: `HERDFIT_FUZZ_CPU_SECONDS=600 cargo test --release --test fuzz -- --exact <parser>`
//! (rounds of `HERDFIT_FUZZ_CASES` cases, each with its own seed, until 600 s of CPU).

#[path = "fuzz/engine.rs"]
mod engine;
#[path = "fuzz/seeds.rs"]
mod seeds;

use engine::{fuzz, Target};
use herdfit::{Error, Result};
use seeds::{head, json, read, repo_file, shared_data};
use std::path::Path;

#[global_allocator]
static HEAP: engine::Counting = engine::Counting;

fn finite(path: &Path, what: &str, v: impl IntoIterator<Item = f64>) -> Result<()> {
    if v.into_iter().all(f64::is_finite) {
        Ok(())
    } else {
        Err(Error::file(path, format!("NaN out: {what} (fuzz check)")))
    }
}

/// Fails the case outright (not an `Err` of the parser): `Ok` with non-finite values.
fn no_nan(r: Result<()>) -> Result<()> {
    if let Err(e) = &r {
        assert!(!e.to_string().contains("(fuzz check)"), "{e}");
    }
    r
}

fn target(name: &'static str, files: Vec<(&str, Vec<u8>)>, parse: engine::Parse) -> Target {
    Target {
        name,
        files: files.into_iter().map(|(n, b)| (n.to_string(), b)).collect(),
        parse,
    }
}

fn tracks_finite(p: &Path, t: &herdfit::data::tracks::Tracks) -> Result<()> {
    no_nan(finite(
        p,
        "tracks",
        t.rows.iter().flat_map(|r| {
            let v = r.vel.unwrap_or([0.0; 3]);
            [r.time, r.pos[0], r.pos[1], r.pos[2], v[0], v[1], v[2]]
        }),
    ))
}

fn clip_finite(p: &Path, c: &herdfit::data::ClipFields) -> Result<()> {
    let f = |a: &[f32]| a.iter().all(|x| x.is_finite());
    let ok = c.density.as_slice().is_none_or(f)
        && c.velocity.as_slice().is_none_or(f)
        && c.dir_variance.as_slice().is_none_or(f);
    no_nan(finite(p, "clip fields", [if ok { 0.0 } else { f64::NAN }]))
}

/// A JSON config: serde (unknown keys rejected) then its `check()`.
macro_rules! config_target {
    ($fn:ident, $name:literal, $ty:ty) => {
        config_target!($fn, $name, $ty, <$ty>::default());
    };
    ($fn:ident, $name:literal, $ty:ty, $seed:expr) => {
        #[test]
        fn $fn() {
            fuzz(target(
                $name,
                vec![("cfg.json", json(&$seed))],
                Box::new(|d| {
                    let p = d.join("cfg.json");
                    let text = std::fs::read(&p).map_err(|e| Error::file(&p, e.to_string()))?;
                    let c: $ty = serde_json::from_slice(&text)
                        .map_err(|e| Error::file(&p, e.to_string()))?;
                    c.check().map_err(|e| e.in_file(&p))
                }),
            ));
        }
    };
}

#[test]
fn params_json() {
    use herdfit::herd::params::Params;
    fuzz(target(
        "params",
        vec![("p.json", read("clip/truth.json"))],
        Box::new(|d| Params::load(&d.join("p.json")).map(|_| ())),
    ));
}

#[test]
fn clip_json_and_fields_npz() {
    use herdfit::data::ClipFields;
    fuzz(target(
        "clip",
        vec![
            ("clip.json", read("clip/clip.json")),
            ("fields.npz", read("clip/fields.npz")),
        ],
        Box::new(|d| {
            let c = ClipFields::load(d)?;
            clip_finite(d, &c)
        }),
    ));
}

#[test]
fn scene_json() {
    use herdfit::herd::author::scene::Scene;
    fuzz(target(
        "scene",
        vec![
            ("scene.json", repo_file("scenes/pasture.json")),
            (
                "pasture/narrow.json",
                repo_file("scenes/pasture/narrow.json"),
            ),
            ("pasture/broad.json", repo_file("scenes/pasture/broad.json")),
        ],
        Box::new(|d| Scene::load(&d.join("scene.json")).map(|_| ())),
    ));
}

#[test]
fn reference_text() {
    use herdfit::data::reference::import_reference;
    let r = |n: &str| repo_file(&format!("tests/data/reference/sample_data_{n}.txt"));
    fuzz(target(
        "reference",
        vec![
            ("s_data_meta.txt", r("meta")),
            ("s_data_frame.txt", r("frame")),
            ("s_data_cell.txt", r("cell")),
        ],
        Box::new(|d| {
            let c = import_reference(&d.join("s"))?;
            clip_finite(d, &c)
        }),
    ));
}

#[test]
fn tracks_csv_and_sidecar() {
    use herdfit::data::tracks::Tracks;
    let v = seeds::repo().join("examples/flocks/v");
    fuzz(target(
        "tracks",
        vec![
            ("t.csv", head(&v.with_extension("csv"), 40)),
            ("t.json", std::fs::read(v.with_extension("json")).unwrap()),
        ],
        Box::new(|d| {
            let p = d.join("t.csv");
            let t = Tracks::load(&p)?;
            tracks_finite(&p, &t)
        }),
    ));
}

#[test]
fn trajectory_csv_without_sidecar() {
    use herdfit::data::tracks::Tracks;
    fuzz(target(
        "trajectory csv",
        vec![("t.csv", read("t.csv"))],
        Box::new(|d| {
            let p = d.join("t.csv");
            let t = Tracks::load(&p)?;
            tracks_finite(&p, &t)
        }),
    ));
}

#[test]
fn eth_ucy_text() {
    use herdfit::data::tracks::read_eth_ucy;
    let src = shared_data().join("pedestrians/eth-ucy/biwi_hotel.txt");
    fuzz(target(
        "eth-ucy",
        vec![("e.txt", head(&src, 60))],
        Box::new(|d| {
            let p = d.join("e.txt");
            let t = read_eth_ucy(&p, 2.5)?;
            tracks_finite(&p, &t)
        }),
    ));
}

#[test]
fn jackdaw_csv() {
    use herdfit::data::jackdaw::load_tracks;
    let src = shared_data().join("jackdaws/transit_05.csv");
    fuzz(target(
        "jackdaw",
        vec![("j.csv", head(&src, 40))],
        Box::new(|d| {
            let p = d.join("j.csv");
            let t = load_tracks(&p)?;
            tracks_finite(&p, &t)
        }),
    ));
}

fn npy_parse(d: &Path) -> Result<()> {
    use herdfit::data::npy_tracks::read_npy_trajectories;
    let p = d.join("t.npy");
    let t = read_npy_trajectories(&p, Some(25.0))?;
    tracks_finite(&p, &t.tracks)?;
    no_nan(finite(
        &p,
        "border",
        t.border.iter().flatten().flat_map(|q| [q[0], q[1]]),
    ))
}

#[test]
fn npy_plain_array() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.npy");
    let a = ndarray::Array3::<f64>::from_shape_fn((3, 2, 2), |(f, i, k)| {
        (f * 4 + i * 2 + k) as f64 * 1.5
    });
    ndarray_npy::write_npy(&p, &a).unwrap();
    fuzz(target(
        "npy array",
        vec![("t.npy", std::fs::read(&p).unwrap())],
        Box::new(npy_parse),
    ));
}

#[test]
fn npy_pickled_dict() {
    // idtracker.ai's own file (the trajectorytools wheel's test data, fetched by
    // scripts/setup-debian.sh into .testdata/).
    let p = seeds::repo().join(".testdata/trajectorytools/test_trajectories_idtrackerai.npy");
    fuzz(target(
        "npy pickle",
        vec![("t.npy", std::fs::read(&p).unwrap())],
        Box::new(npy_parse),
    ));
}

#[test]
fn camera_json() {
    use herdfit::data::camera::Camera;
    use herdfit::data::tracks::Units;
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("cam.json");
    #[rustfmt::skip]
    Camera::look_at(Units::Metres, 64, 48, 60.0, [0.0, -10.0, 2.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0])
        .unwrap()
        .save(&p)
        .unwrap();
    fuzz(target(
        "camera",
        vec![("cam.json", std::fs::read(&p).unwrap())],
        Box::new(|d| {
            let p = d.join("cam.json");
            let c = Camera::load(&p)?;
            let r = c.rotation.iter().flatten().copied();
            no_nan(finite(
                &p,
                "camera",
                [c.fx, c.fy, c.cx, c.cy].into_iter().chain(r),
            ))
        }),
    ));
}

#[test]
fn gltf_glb() {
    use herdfit::data::gltf::{read_glb, to_glb, GltfConfig};
    use herdfit::data::tracks::Tracks;
    let v = seeds::repo().join("examples/flocks/v.csv");
    let t = Tracks::load(&v).unwrap();
    let cfg = GltfConfig {
        mesh: false,
        ..GltfConfig::default()
    };
    let few = Tracks::new(
        t.meta.clone(),
        t.rows.iter().filter(|r| r.frame < 3).cloned().collect(),
    )
    .unwrap();
    let (glb, _) = to_glb(&few, &cfg).unwrap();
    fuzz(target(
        "gltf",
        vec![("t.glb", glb)],
        Box::new(|d| {
            let p = d.join("t.glb");
            let g = read_glb(&p)?;
            // What `lift` does with a GLB: sample its animation.
            let poses = g.sample(0.5).map_err(|e| e.in_file(&p))?;
            no_nan(finite(&p, "poses", poses.iter().flat_map(|q| q.1)))
        }),
    ));
}

#[test]
fn init_csv() {
    use herdfit::data::agents::read_init_csv;
    let init = b"id,x,y,vx,vy\n0,1.5,2,0.5,0\n1,-3,4.25,0,1\n2,0,0,-1,-1\n".to_vec();
    fuzz(target(
        "init csv",
        vec![("i.csv", init)],
        Box::new(|d| {
            let p = d.join("i.csv");
            let rows = read_init_csv(&p)?;
            no_nan(finite(
                &p,
                "rows",
                rows.iter().flat_map(|r| [r.x, r.y, r.vx, r.vy]),
            ))
        }),
    ));
}

#[test]
fn obstacle_cells_json() {
    use herdfit::data::cells::read_cells;
    fuzz(target(
        "cells",
        vec![("c.json", br#"{"cells": [[0, 1], [3, 2], [7, 7]]}"#.to_vec())],
        Box::new(|d| read_cells(&d.join("c.json"), 8, 8).map(|_| ())),
    ));
}

#[test]
fn obstacle_polygons_json() {
    use herdfit::data::obstacle_polygons::ObstaclePolygons;
    fuzz(target(
        "obstacle polygons",
        vec![(
            "rocks.json",
            br#"{"schema": "herdfit.obstacle-polygons/1",
  "polygons": [[[10, 10], [60, 12], [40, 50]], [[100, 0], [160, 0], [160, 90], [100, 90]]]}"#
                .to_vec(),
        )],
        Box::new(|d| {
            let p = ObstaclePolygons::load(&d.join("rocks.json"))?;
            // Painting any accepted file into a frame neither panics nor allocates past it.
            let m = p.mask(64, 48);
            assert_eq!(m.len(), 64 * 48);
            Ok(())
        }),
    ));
}

#[test]
fn recording_json() {
    use herdfit::herd::sim::Recording;
    fuzz(target(
        "recording",
        vec![("rec.json", read("rec.json"))],
        Box::new(|d| Recording::load(&d.join("rec.json")).map(|_| ())),
    ));
}

#[test]
fn checkpoint_json() {
    use herdfit::herd::fit::checkpoint::{ZoneStarts, ZoneState};
    use herdfit::herd::fit::{Checkpoint, FitConfig, OptState};
    use herdfit::herd::params::N_PARAMS;
    let k = Checkpoint {
        schema: herdfit::herd::fit::checkpoint::CHECKPOINT_SCHEMA.into(),
        epochs_done: 1,
        theta: [0.5; N_PARAMS],
        opt: OptState::new(N_PARAMS),
        log: Vec::new(),
        config: FitConfig {
            frames: 0..12,
            ..FitConfig::default()
        },
        start: [0.25; N_PARAMS],
        // A zone fit's checkpoint, so that the zones' checks are fuzzed too.
        zone_starts: ZoneStarts {
            names: vec!["west".into(), "east".into()],
            starts: vec![[0.75; N_PARAMS]],
        },
        zones: vec![ZoneState {
            theta: [0.4; N_PARAMS],
            opt: OptState::new(N_PARAMS),
        }],
    };
    fuzz(target(
        "checkpoint",
        vec![("checkpoint.json", json(&k))],
        Box::new(|d| Checkpoint::load(&d.join("checkpoint.json")).map(|_| ())),
    ));
}

/// A flock shape file with its first two example frames only (≈ 4 kB instead of 44 kB).
fn few_frames(b: &[u8]) -> Vec<u8> {
    let mut v: serde_json::Value = serde_json::from_slice(b).unwrap();
    if let Some(f) = v["frames"].as_array_mut() {
        f.truncate(2);
    }
    json(&v)
}

#[test]
fn flock_shape_json() {
    use herdfit::flock::extract::ShapeParams;
    fuzz(target(
        "flock shape",
        vec![("shape.json", few_frames(&read("shape.json")))],
        Box::new(|d| ShapeParams::load(&d.join("shape.json")).map(|_| ())),
    ));
}

#[test]
fn crowd_model_json() {
    use herdfit::crowd::model::CrowdModel;
    fuzz(target(
        "crowd model",
        vec![("model.json", read("model.json"))],
        Box::new(|d| CrowdModel::load(&d.join("model.json")).map(|_| ())),
    ));
}

#[test]
fn crowd_layout_json() {
    use herdfit::crowd::layout::Layout;
    fuzz(target(
        "crowd layout",
        vec![("layout.json", json(&Layout::default()))],
        Box::new(|d| Layout::load(&d.join("layout.json")).map(|_| ())),
    ));
}

#[test]
fn lift_config_json() {
    use herdfit::lift::LiftConfig;
    fuzz(target(
        "lift config",
        vec![("lift.json", json(&LiftConfig::default()))],
        Box::new(|d| LiftConfig::load(&d.join("lift.json")).map(|_| ())),
    ));
}

config_target!(
    fit_config_json,
    "fit config",
    herdfit::herd::fit::FitConfig,
    herdfit::herd::fit::FitConfig {
        frames: 0..12,
        ..Default::default()
    }
);
config_target!(
    crowd_learn_config_json,
    "crowd learn config",
    herdfit::crowd::model::LearnConfig
);
config_target!(
    crowd_sim_config_json,
    "crowd sim config",
    herdfit::crowd::sim::SimConfig
);
config_target!(
    crowd_eval_config_json,
    "crowd eval config",
    herdfit::crowd::eval::EvalConfig
);
config_target!(
    flock_extract_config_json,
    "flock extract config",
    herdfit::flock::extract::ExtractConfig
);
config_target!(
    flock_animate_config_json,
    "flock animate config",
    herdfit::flock::animate::AnimateConfig
);
config_target!(
    boids_config_json,
    "boids config",
    herdfit::lift::boids::BoidsConfig
);
#[cfg(feature = "video")]
config_target!(
    extract_settings_json,
    "extract settings",
    herdfit::video::extract::ExtractConfig
);

/// Regressions the fuzz found in the GLB reader: NaN in the buffer reached the sampled poses,
/// and out-of-range sampler/node indices were indexed unchecked.
#[test]
fn glb_with_nan_values_or_bad_indices_is_an_error() {
    use herdfit::data::gltf::{read_glb, to_glb, GltfConfig};
    use herdfit::data::tracks::Tracks;
    let t = Tracks::load(&seeds::repo().join("examples/flocks/v.csv")).unwrap();
    let cfg = GltfConfig {
        mesh: false,
        ..GltfConfig::default()
    };
    let (glb, _) = to_glb(&t, &cfg).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.glb");
    std::fs::write(&p, &glb).unwrap();
    let good = read_glb(&p).unwrap();
    assert!(good.sample(0.5).is_ok());
    let mut nan = read_glb(&p).unwrap();
    for c in nan.bin.chunks_exact_mut(4) {
        c.copy_from_slice(&f32::NAN.to_le_bytes());
    }
    let e = nan.sample(0.5).unwrap_err().to_string();
    assert!(e.contains("non-finite"), "{e}");
    let mut idx = read_glb(&p).unwrap();
    idx.root.animations[0].channels[0].sampler = gltf_json::Index::new(9999);
    let e = idx.sample(0.5).unwrap_err().to_string();
    assert!(e.contains("sampler index"), "{e}");
}
