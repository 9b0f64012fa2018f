//! Authoring: the two example scenes, a destination behind a U-shaped obstacle, and bad scenes.

mod common;
use common::{herdfit, ok, s};
use std::path::{Path, PathBuf};

fn scenes() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes")
}

/// (frame, x, y) of every agent, per frame.
fn trajectories(dir: &Path) -> Vec<Vec<[f64; 2]>> {
    let text = std::fs::read_to_string(dir.join("trajectories.csv")).unwrap();
    let mut out: Vec<Vec<[f64; 2]>> = Vec::new();
    for l in text.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        let f: usize = c[0].parse().unwrap();
        if out.len() <= f {
            out.push(Vec::new());
        }
        out[f].push([c[3].parse().unwrap(), c[4].parse().unwrap()]);
    }
    out
}

fn dist_to_polyline(p: [f64; 2], poly: &[[f64; 2]]) -> f64 {
    poly.windows(2)
        .map(|w| {
            let (a, b) = (w[0], w[1]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let l2 = d[0] * d[0] + d[1] * d[1];
            let t = (((p[0] - a[0]) * d[0] + (p[1] - a[1]) * d[1]) / l2).clamp(0.0, 1.0);
            (p[0] - a[0] - t * d[0]).hypot(p[1] - a[1] - t * d[1])
        })
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn pasture_follows_the_arrow_avoids_obstacles_and_shows_two_behaviours() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("pasture");
    let scene_path = scenes().join("pasture.json");
    ok(&["author", s(&scene_path), "--out", s(&out)]);
    for f in [
        "trajectories.csv",
        "navigation.png",
        "snapshot-0.png",
        "snapshot-2.png",
        "report.json",
    ] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let scene = herdfit::herd::author::Scene::load(&scene_path).unwrap();
    let arrow = &scene.file.arrows[0];
    let end = arrow[arrow.len() - 1];
    let frames = trajectories(&out);
    let centroid: Vec<[f64; 2]> = frames
        .iter()
        .map(|a| {
            let n = a.len() as f64;
            [
                a.iter().map(|p| p[0]).sum::<f64>() / n,
                a.iter().map(|p| p[1]).sum::<f64>() / n,
            ]
        })
        .collect();
    // The centroid reaches the arrow's end (within 6 BL) ...
    let reach = centroid
        .iter()
        .position(|c| (c[0] - end[0]).hypot(c[1] - end[1]) <= 6.0)
        .expect("the herd reaches the end of the arrow");
    // ... staying within 6 BL of the arrow all the way.
    let worst = centroid[..=reach]
        .iter()
        .map(|c| dist_to_polyline(*c, arrow))
        .fold(0.0, f64::max);
    assert!(worst <= 6.0, "centroid strays {worst} BL from the arrow");
    // No agent centre inside an obstacle (or outside the world) in any frame.
    for (f, agents) in frames.iter().enumerate() {
        for p in agents {
            assert!(
                !scene.blocked(*p),
                "frame {f}: agent at {p:?} is inside an obstacle"
            );
        }
    }
    // The two behaviour regions give measurably different herds.
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let (a, b) = (&r["regions"][1], &r["regions"][2]);
    let da = (a["aspect_ratio"].as_f64().unwrap() - b["aspect_ratio"].as_f64().unwrap()).abs();
    let dp = (a["polarization"].as_f64().unwrap() - b["polarization"].as_f64().unwrap()).abs();
    assert!(
        da > 0.3 || dp > 0.05,
        "aspect ratio differs by {da}, polarization by {dp}"
    );
}

#[test]
fn anthill_runs_with_a_predator_and_keeps_out_of_the_hill() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("anthill");
    let scene_path = scenes().join("anthill.json");
    ok(&["author", s(&scene_path), "--out", s(&out)]);
    let scene = herdfit::herd::author::Scene::load(&scene_path).unwrap();
    let frames = trajectories(&out);
    for agents in &frames {
        assert!(agents.iter().all(|p| !scene.blocked(*p)));
    }
    // The herd circles the hill counter-clockwise: the centroid's angle about the hill's centre
    // advances.
    let ang = |a: &Vec<[f64; 2]>| {
        let n = a.len() as f64;
        let c = [
            a.iter().map(|p| p[0]).sum::<f64>() / n - 40.0,
            a.iter().map(|p| p[1]).sum::<f64>() / n - 40.0,
        ];
        c[1].atan2(c[0])
    };
    let (a0, a1) = (ang(&frames[0]), ang(&frames[frames.len() / 2]));
    let mut d = a1 - a0;
    if d < 0.0 {
        d += std::f64::consts::TAU;
    }
    assert!(d > 0.5 && d < std::f64::consts::PI + 0.5, "turned {d} rad");
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(r["predator"].as_array().unwrap().len(), frames.len() - 1);
}

fn write_scene(dir: &Path, name: &str, v: &serde_json::Value) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, serde_json::to_string_pretty(v).unwrap()).unwrap();
    p
}

fn u_scene() -> serde_json::Value {
    serde_json::json!({
        "schema": "herdfit.scene/1",
        "world": {"width": 60, "height": 40, "cell_size": 2},
        "obstacles": {"polygons": [
            [[20, 28], [34, 28], [34, 30], [20, 30]],
            [[20, 10], [34, 10], [34, 12], [20, 12]],
            [[32, 10], [34, 10], [34, 30], [32, 30]]
        ]},
        "destination": {"point": [52, 20]},
        "spawn": {"count": 60, "centre": [27, 20], "size": [6, 10], "heading_deg": 0},
        "duration": 70, "fps": 25, "seed": 2
    })
}

#[test]
fn a_herd_behind_a_u_shaped_obstacle_reaches_its_destination() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path(), "u.json", &u_scene());
    let out = dir.path().join("u");
    ok(&["author", s(&scene), "--out", s(&out)]);
    let frames = trajectories(&out);
    let near = |a: &Vec<[f64; 2]>| {
        a.iter()
            .filter(|p| (p[0] - 52.0).hypot(p[1] - 20.0) <= 8.0)
            .count() as f64
            / a.len() as f64
    };
    assert!(near(&frames[0]) == 0.0);
    let best = frames.iter().map(near).fold(0.0, f64::max);
    assert!(
        best >= 0.8,
        "at best {best} of the herd within 8 BL of the goal"
    );
}

#[test]
fn bad_scenes_name_the_json_path() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("out");
    let cases: Vec<(serde_json::Value, &str)> = {
        let mut v = Vec::new();
        let mut x = u_scene();
        x["colour"] = "red".into();
        v.push((x, "colour"));
        let mut x = u_scene();
        x["obstacles"]["polygons"][1] = serde_json::json!([[1, 1], [2, 2]]);
        v.push((x, "obstacles.polygons[1]"));
        let mut x = u_scene();
        x["spawn"]["centre"] = serde_json::json!([33, 20]);
        v.push((x, "spawn.centre"));
        let mut x = u_scene();
        x["regions"] =
            serde_json::json!([{"polygon": [[0, 0], [10, 0], [10, 10]], "params": "missing.json"}]);
        v.push((x, "regions[0].params"));
        let mut x = u_scene();
        x["arrows"] = serde_json::json!([[[5, 5], [70, 5]]]);
        v.push((x, "arrows[0][1]"));
        let mut x = u_scene();
        x["regions"] = serde_json::json!([{"polygon": [[0, 0], [10, 0]], "params": "p.json"}]);
        v.push((x, "regions[0].polygon"));
        let mut x = u_scene();
        x["spawn"]["count"] = 0.into();
        v.push((x, "spawn.count"));
        v
    };
    for (k, (scene, needle)) in cases.into_iter().enumerate() {
        let p = write_scene(d, &format!("bad{k}.json"), &scene);
        let o = herdfit(&["author", s(&p), "--out", s(&out)]);
        assert_eq!(o.status.code(), Some(1), "case {k}");
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        assert!(
            e.contains(&format!("bad{k}.json")) && e.contains(needle),
            "case {k}: {e}"
        );
        assert!(!out.exists());
    }
}

#[cfg(feature = "video")]
#[test]
fn mask_obstacles_and_video_output() {
    use opencv::prelude::MatTraitManual;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A 60×40 mask whose right third is an obstacle.
    let mut m = opencv::core::Mat::new_rows_cols_with_default(
        40,
        60,
        opencv::core::CV_8UC1,
        opencv::core::Scalar::all(0.0),
    )
    .unwrap();
    {
        let data = m.data_bytes_mut().unwrap();
        for y in 0..40 {
            for x in 40..60 {
                data[y * 60 + x] = 255;
            }
        }
    }
    opencv::imgcodecs::imwrite(s(&d.join("mask.png")), &m, &opencv::core::Vector::new()).unwrap();
    let mut scene = u_scene();
    scene["obstacles"] = serde_json::json!({"mask": "mask.png"});
    scene["destination"] = serde_json::json!({"point": [30, 20]});
    scene["spawn"] = serde_json::json!({"count": 30, "centre": [10, 20], "size": [6, 6]});
    scene["duration"] = 2.into();
    let p = write_scene(d, "mask.json", &scene);
    let loaded = herdfit::herd::author::Scene::load(&p).unwrap();
    assert!(loaded.blocked([50.0, 20.0]) && !loaded.blocked([30.0, 20.0]));
    assert_eq!(
        loaded.obstacles.iter().filter(|&&v| v == 1).count(),
        10 * 20
    );
    let out = d.join("out");
    ok(&["author", s(&p), "--out", s(&out), "--video"]);
    assert!(out.join("herd.avi").metadata().unwrap().len() > 1000);
}

#[test]
fn same_scene_same_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let mut scene = u_scene();
    scene["duration"] = 3.into();
    let p = write_scene(dir.path(), "u.json", &scene);
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    ok(&["author", s(&p), "--out", s(&a)]);
    ok(&["author", s(&p), "--out", s(&b)]);
    for f in ["trajectories.csv", "report.json"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}"
        );
    }
}

/// A corridor scene 40 × 10 BL (2-BL cells) with an arrow along it, sources at the left edge
/// and sinks at the right edge: a stream of animals through an authored valley.
fn stream_scene(boundary: serde_json::Value) -> serde_json::Value {
    let gates = |ix: usize, side: &str| -> Vec<serde_json::Value> {
        (1..4)
            .map(|iy| serde_json::json!({"cell": [ix, iy], "side": side}))
            .collect()
    };
    let mut b = boundary;
    b["entries"] = serde_json::Value::Array(gates(0, "left"));
    b["exits"] = serde_json::Value::Array(gates(19, "right"));
    serde_json::json!({
        "schema": "herdfit.scene/1",
        "world": {"width": 40, "height": 10, "cell_size": 2},
        "arrows": [[[0, 5], [40, 5]]],
        "spawn": {"count": 60, "centre": [20, 5], "size": [36, 4], "heading_deg": 0},
        "boundary": b,
        "duration": 20, "fps": 25, "seed": 4
    })
}

#[test]
fn a_stream_through_an_authored_corridor_keeps_its_count_over_500_frames() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(
        dir.path(),
        "stream.json",
        &stream_scene(serde_json::json!({"count": 60})),
    );
    let out = dir.path().join("stream");
    ok(&["author", s(&scene), "--out", s(&out)]);
    let frames = trajectories(&out);
    assert_eq!(frames.len(), 501);
    let x_max = frames
        .iter()
        .flatten()
        .map(|p| p[0])
        .fold(f64::MIN, f64::max);
    // The herd (1 BL/s) crosses the 40-BL corridor in about 40 s: over the 20-s run a third of
    // it leaves at the right and is replaced at the left.
    let inside = |f: &Vec<[f64; 2]>| f.iter().filter(|p| (0.0..=40.0).contains(&p[0])).count();
    for (k, f) in frames.iter().enumerate() {
        let n = inside(f) as f64;
        assert!(
            (n - 60.0).abs() <= 6.0,
            "frame {k}: {n} agents in the world"
        );
    }
    assert!(
        x_max <= 40.0,
        "an agent was written outside the world at x = {x_max}"
    );
    // Entrants walk in from outside the left edge, never appear inside the world.
    assert!(frames.iter().flatten().any(|p| p[0] < 0.0));
    let report: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    let left = report["boundary"]["left"][1].as_u64().unwrap();
    let entered = report["boundary"]["entered"].as_u64().unwrap();
    assert!(left >= 10, "only {left} left through the exits");
    assert!(
        entered.abs_diff(left) <= 6,
        "entered {entered}, left {left}"
    );
}

#[test]
fn a_scene_without_exits_keeps_its_walls_and_a_rate_source_adds_agents() {
    let dir = tempfile::tempdir().unwrap();
    let mut v = stream_scene(serde_json::json!({"rate": 2.0}));
    v["boundary"]["exits"] = serde_json::json!([]);
    let scene = write_scene(dir.path(), "rate.json", &v);
    let out = dir.path().join("rate");
    ok(&["author", s(&scene), "--out", s(&out)]);
    let frames = trajectories(&out);
    // 2 agents/s over 20 s: 40 more, nobody leaves (the right edge is a wall).
    assert_eq!(frames[500].len(), 100);
    assert!(frames[500].iter().all(|p| p[0] <= 40.0));
}

#[test]
fn scene_boundaries_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    for (boundary, want) in [
        (serde_json::json!({}), "entries need a count"),
        (serde_json::json!({"count": 5, "rate": 1.0}), "not both"),
        (serde_json::json!({"rate": -1.0}), "boundary.rate"),
    ] {
        let p = write_scene(dir.path(), "b.json", &stream_scene(boundary));
        let o = herdfit(&["author", s(&p), "--out", s(&dir.path().join("o"))]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && e.contains("b.json") && e.contains(want),
            "{e}"
        );
    }
    let mut v = stream_scene(serde_json::json!({"count": 5}));
    v["boundary"]["entries"][0]["cell"] = serde_json::json!([3, 1]);
    let p = write_scene(dir.path(), "side.json", &v);
    let o = herdfit(&["author", s(&p), "--out", s(&dir.path().join("o"))]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("entries[0]"), "{e}");
    assert!(!dir.path().join("o").exists());
}
