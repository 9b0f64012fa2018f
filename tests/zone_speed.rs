//! Zones with a fixed speed and zones from a mask image (issue #17 item 1, paper §7.2.4: the
//! seals' 3.0 BL/s in water and 0.5 on land): the speed step follows the zone's speed, the
//! decisions record it and replay exactly, `synth`/`fit`/`validate` carry it through a bundle,
//! and a mask image assigns the same cells as the equivalent polygons.

mod common;
use common::{fails, ok, s};
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::{ClipFields, Grid};
use herdfit::herd::params::Params;
use herdfit::herd::sim::{
    random_herd, theta_tensor, Decide, Guidance, HerdSpec, HerdState, Model, Recording, SpeedMap,
    World,
};
use herdfit::herd::zones::Zones;
use rand::SeedableRng;
use std::path::{Path, PathBuf};

/// West of x = 0 the speed is fixed at 3.0 BL/s, east of it at 0.5 (a 100 × 100 BL grid).
fn two_speed_world() -> World {
    let grid = Grid {
        origin: [-50.0, -50.0],
        cell_size: 5.0,
        nx: 20,
        ny: 20,
    };
    let speed = (0..400)
        .map(|c| Some(if c % 20 < 10 { 3.0 } else { 0.5 }))
        .collect();
    World {
        obstacles: None,
        guidance: Guidance::None,
        fixed_speed: Some(SpeedMap { grid, speed }),
    }
}

#[test]
fn a_fixed_zone_speed_is_the_mean_speed_there_and_replays_exactly() {
    let dev = cpu_device(Precision::F64).unwrap();
    let world = two_speed_world();
    let mut params = Params::default();
    params.speed.mean = 1.0;
    params.speed.std = 0.2;
    params.speed.max = 2.0;
    let model = Model {
        params,
        world: world.clone(),
        dt: 0.1,
        force_kernel: herdfit::herd::sim::ForceKernel::default(),
    };
    let mut spec = HerdSpec::standard(300);
    spec.density = 0.05;
    let rows = random_herd(&spec, &model.params.speed, &World::open(), 4).unwrap();
    let theta = theta_tensor(&model.params.to_vec(), &dev);
    let mut rec = Recording::new(rows.len());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    // Which agents stayed west (or east) of x = 0 over the whole run.
    let mut stayed = vec![[true, true]; rows.len()];
    for (k, r) in rows.iter().enumerate() {
        stayed[k] = [r.x < 0.0, r.x >= 0.0];
    }
    let steps = 100; // 10 s: e^{-10} of the start's speed is left (θ_OU = 1/s)
    let end = model
        .rollout(
            &theta,
            HerdState::from_rows(&rows, &dev),
            steps,
            Decide::Live {
                rng: &mut rng,
                record: Some(&mut rec),
            },
            |_, _, next| {
                for (k, p) in next.snapshot()?.pos.iter().enumerate() {
                    stayed[k][0] &= p[0] < 0.0;
                    stayed[k][1] &= p[0] >= 0.0;
                }
                Ok(())
            },
        )
        .unwrap()
        .snapshot()
        .unwrap();
    // Every decision records the zone speed at the agent's position.
    let first = &rec.steps[0];
    assert_eq!(first.fixed_speed.len(), rows.len());
    for (r, v) in rows.iter().zip(&first.fixed_speed) {
        assert_eq!(*v, Some(if r.x < 0.0 { 3.0 } else { 0.5 }));
    }
    let mean = |side: usize| {
        let v: Vec<f64> = (0..rows.len())
            .filter(|&k| stayed[k][side])
            .map(|k| end.speed[k])
            .collect();
        assert!(
            v.len() >= 40,
            "only {} agents stayed on side {side}",
            v.len()
        );
        v.iter().sum::<f64>() / v.len() as f64
    };
    // The stationary spread is 0.2 / √2 ≈ 0.14 BL/s: the means of ≥ 40 agents are within 0.1.
    let (west, east) = (mean(0), mean(1));
    assert!((west - 3.0).abs() < 0.1, "west mean speed {west}");
    assert!((east - 0.5).abs() < 0.1, "east mean speed {east}");
    // The cap leaves a fixed speed above the set's v_max its room (3.0 > max 2.0).
    assert!(end.speed.iter().any(|&v| v > 2.0));
    // Through a file and back, the replay gives the same herd.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.json");
    rec.save(&path).unwrap();
    let rec2 = Recording::load(&path).unwrap();
    assert_eq!(rec2, rec);
    let open = Model {
        world: World::open(),
        ..model.clone()
    };
    let replayed = open
        .rollout::<rand_chacha::ChaCha8Rng>(
            &theta,
            HerdState::from_rows(&rows, &dev),
            steps,
            Decide::Replay(&rec2),
            |_, _, _| Ok(()),
        )
        .unwrap()
        .snapshot()
        .unwrap();
    assert_eq!(
        replayed, end,
        "the replay takes the speeds from the recording"
    );
}

fn write_json(path: &Path, v: serde_json::Value) -> PathBuf {
    std::fs::write(path, v.to_string()).unwrap();
    path.to_path_buf()
}

/// West half (x < 12 BL) and east half of the 24 × 18 BL test clip.
fn rect(x0: f64, x1: f64) -> serde_json::Value {
    serde_json::json!([[x0, 0.0], [x1, 0.0], [x1, 18.0], [x0, 18.0]])
}

/// Mean |velocity| weighted by density over the cells of columns `cols` of the clip.
fn mean_speed(clip: &ClipFields, cols: std::ops::Range<usize>) -> f64 {
    let (mut m, mut n) = (0.0, 0.0);
    for f in 0..clip.frames() {
        for iy in 0..clip.meta.ny {
            for ix in cols.clone() {
                let d = clip.density[[f, iy, ix]] as f64;
                let v = (clip.velocity[[f, iy, ix, 0]] as f64)
                    .hypot(clip.velocity[[f, iy, ix, 1]] as f64);
                m += d * v;
                n += d;
            }
        }
    }
    m / n
}

#[test]
fn zone_speeds_go_from_synth_through_the_fit_to_validate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let base = d.join("base.json");
    let mut p = Params::default();
    p.speed.mean = 1.5;
    p.speed.std = 0.2;
    p.save(&base).unwrap();
    let pv = serde_json::to_value(&p).unwrap();
    let truth = write_json(
        &d.join("truth.json"),
        serde_json::json!({"schema": "herdfit.param-sets/1", "sets": [
            {"name": "water", "polygon": rect(0.0, 12.0), "speed": 3.0, "params": pv},
            {"name": "land", "polygon": rect(12.0, 24.0), "speed": 0.5, "params": pv}]}),
    );
    let clip = d.join("clip");
    #[rustfmt::skip]
    ok(&["synth", "--agents", "80", "--frame-count", "40", "--fps", "5", "--grid-size", "8x6",
         "--cell-size", "3", "--seed", "3", "--params", s(&base), "--zone-sets", s(&truth),
         "--out", s(&clip)]);
    let c = ClipFields::load(&clip).unwrap();
    // Field velocities are means over a cell's agents (≤ their speed). The land's first column
    // holds agents still slowing down (eq. 6 relaxes at θ_OU = 1/s), so it is left out.
    let (west, east) = (mean_speed(&c, 0..4), mean_speed(&c, 5..8));
    assert!(west > 2.6 && west < 3.2, "water zone's field speed {west}");
    assert!(east > 0.35 && east < 0.8, "land zone's field speed {east}");
    let zones = |name: &str, speeds: bool| {
        let z = |n: &str, x0: f64, x1: f64, v: f64| {
            let mut o = serde_json::json!({"name": n, "polygon": rect(x0, x1)});
            if speeds {
                o["speed"] = serde_json::json!(v);
            }
            o
        };
        write_json(
            &d.join(name),
            serde_json::json!({"schema": "herdfit.zones/1", "zones": [
                z("water", 0.0, 12.0, 3.0), z("land", 12.0, 24.0, 0.5)]}),
        )
    };
    let fit = |zfile: &Path, out: &str| {
        let out = d.join(out);
        #[rustfmt::skip]
        ok(&["fit", s(&clip), "--zones", s(zfile), "--frames", "0..20", "--out", s(&out),
             "--epochs", "1", "--window", "3", "--eval-seeds", "1", "--loss", "fields"]);
        out
    };
    let with = fit(&zones("zones.json", true), "with.json");
    let without = fit(&zones("plain.json", false), "without.json");
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&with).unwrap()).unwrap();
    assert_eq!(b["sets"][0]["speed"], 3.0);
    assert_eq!(b["sets"][1]["speed"], 0.5);
    let validate = |bundle: &Path, rep: &str| -> serde_json::Value {
        let rep = d.join(rep);
        #[rustfmt::skip]
        let printed = ok(&["validate", s(&clip), "--params", s(bundle), "--baseline", s(&base),
                           "--seeds", "2", "--out", s(&rep)]);
        assert!(printed.contains("# herdfit zone validation"), "{printed}");
        for f in ["report.json", "report.md", "zones.png"] {
            assert!(rep.join(f).is_file(), "{f} missing");
        }
        serde_json::from_str(&std::fs::read_to_string(rep.join("report.json")).unwrap()).unwrap()
    };
    let r_with = validate(&with, "rep-with");
    let r_without = validate(&without, "rep-without");
    assert_eq!(r_with["schema"], "herdfit.zone-validation/1");
    assert_eq!(r_with["zones"][0]["name"], "water");
    assert_eq!(r_with["zones"][0]["cells"], 24);
    assert_eq!(r_with["zones"][0]["speed"], 3.0);
    assert!(r_without["zones"][0]["speed"].is_null());
    let verr = |r: &serde_json::Value| r["sets"][0]["velocity_error"]["mean"].as_f64().unwrap();
    // Told the zones' speeds, the held-out velocity error is far lower than without them.
    let (a, b) = (verr(&r_with), verr(&r_without));
    eprintln!("held-out velocity error: told the speeds {a:.4}, not told {b:.4}");
    assert!(
        a < 0.8 * b,
        "velocity error with the speeds {a}, without {b}"
    );
    // A baseline of other zones is refused; a bad speed is a one-line error.
    let other = write_json(
        &d.join("other.json"),
        serde_json::json!({"schema": "herdfit.param-sets/1", "sets": [
            {"name": "a", "polygon": rect(0.0, 9.0), "params": pv},
            {"name": "b", "polygon": rect(9.0, 24.0), "params": pv}]}),
    );
    #[rustfmt::skip]
    let e = fails(&["validate", s(&clip), "--params", s(&with), "--baseline", s(&other),
                    "--out", s(&d.join("rep-other"))]);
    assert!(
        e.contains("other.json") && e.contains("zones are not"),
        "{e}"
    );
    assert!(!d.join("rep-other").exists());
    let bad = write_json(
        &d.join("bad-speed.json"),
        serde_json::json!({"schema": "herdfit.zones/1", "zones": [
            {"name": "water", "polygon": rect(0.0, 12.0), "speed": -1.0},
            {"name": "land", "polygon": rect(12.0, 24.0)}]}),
    );
    #[rustfmt::skip]
    let e = fails(&["fit", s(&clip), "--zones", s(&bad), "--out", s(&d.join("x.json"))]);
    assert!(
        e.contains("bad-speed.json") && e.contains("zones[0].speed ('water'): -1"),
        "{e}"
    );
    assert!(!d.join("x.json").exists());
}

/// A binary PPM (which OpenCV reads) of `w × h` pixels coloured by `colour(x, y)`, row 0 on top.
fn ppm(path: &Path, w: usize, h: usize, colour: impl Fn(usize, usize) -> [u8; 3]) {
    let mut b = format!("P6\n{w} {h}\n255\n").into_bytes();
    for y in 0..h {
        for x in 0..w {
            b.extend(colour(x, y));
        }
    }
    std::fs::write(path, b).unwrap();
}

#[test]
fn a_mask_image_assigns_the_cells_its_polygons_would() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip_dir = common::small_clip(d, 60, 12, 2);
    let clip = ClipFields::load(&clip_dir).unwrap();
    // 8 × 6 cells of 3 BL; the mask is 80 × 60 px: red west of x = 9 BL (px 30), blue east, a
    // slightly off blue (JPEG-like noise) in the top-right corner, a grey seam of 2 px at the
    // border (anti-aliasing: cells keep their majority colour).
    ppm(&d.join("zones.ppm"), 80, 60, |x, y| match x {
        29 | 30 => [128, 128, 128],
        _ if x < 30 => [255, 0, 0],
        _ if y < 10 && x > 70 => [20, 10, 235],
        _ => [0, 0, 255],
    });
    let mask = write_json(
        &d.join("mask-zones.json"),
        serde_json::json!({"schema": "herdfit.zones/1", "mask": "zones.ppm", "zones": [
            {"name": "west", "colour": "#ff0000", "speed": 2.0},
            {"name": "east", "colour": "#0000ff"}]}),
    );
    let poly = write_json(
        &d.join("poly-zones.json"),
        serde_json::json!({"schema": "herdfit.zones/1", "zones": [
            {"name": "west", "polygon": rect(0.0, 9.0)},
            {"name": "east", "polygon": rect(9.0, 24.0)}]}),
    );
    let zm = Zones::load(&mask, &clip).unwrap();
    let zp = Zones::load(&poly, &clip).unwrap();
    assert_eq!(zm.cell_zone, zp.cell_zone);
    assert_eq!(zm.cell_zone.iter().filter(|z| **z == Some(0)).count(), 18);
    let map = zm.speed_map(&clip.grid()).unwrap();
    assert_eq!(map.at([1.0, 1.0]), Some(2.0));
    assert_eq!(map.at([20.0, 1.0]), None);
    // The fit takes it and its bundle keeps the mask (absolute) and the colours.
    let out = d.join("sets.json");
    #[rustfmt::skip]
    ok(&["fit", s(&clip_dir), "--zones", s(&mask), "--out", s(&out), "--epochs", "1",
         "--window", "3", "--eval-seeds", "1", "--loss", "fields"]);
    let b: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert!(Path::new(b["mask"].as_str().unwrap()).is_absolute());
    assert_eq!(b["sets"][0]["colour"], "#ff0000");
    assert_eq!(b["sets"][0]["speed"], 2.0);
    // Bad masks: a colour no zone has, a colour twice, no colour, no mask file, a colour
    // without a mask — one line each naming the file, nothing written.
    ppm(&d.join("grey.ppm"), 80, 60, |x, _| {
        if x < 40 {
            [255, 0, 0]
        } else {
            [128, 128, 128]
        }
    });
    let run = |name: &str, v: serde_json::Value| {
        let z = write_json(&d.join(name), v);
        let o = d.join("bad-out.json");
        #[rustfmt::skip]
        let e = fails(&["fit", s(&clip_dir), "--zones", s(&z), "--out", s(&o), "--epochs", "1",
                        "--window", "3"]);
        assert!(!o.exists());
        e
    };
    let two = |c0: &str, c1: &str| serde_json::json!([{"name": "west", "colour": c0}, {"name": "east", "colour": c1}]);
    let e = run(
        "grey.json",
        serde_json::json!({"schema": "herdfit.zones/1", "mask": "grey.ppm", "zones": two("#ff0000", "#0000ff")}),
    );
    assert!(
        e.contains("grey.json")
            && e.contains(
                "cell (4, 0), centre (13.500, 1.500), is in no zone: the mask shows #808080"
            ),
        "{e}"
    );
    let e = run(
        "same.json",
        serde_json::json!({"schema": "herdfit.zones/1", "mask": "zones.ppm", "zones": two("#ff0000", "#FF0000")}),
    );
    assert!(
        e.contains("zones 'west' and 'east' have the same colour #FF0000"),
        "{e}"
    );
    let e = run(
        "nocolour.json",
        serde_json::json!({"schema": "herdfit.zones/1", "mask": "zones.ppm", "zones": [
            {"name": "west", "colour": "#ff0000"}, {"name": "east"}]}),
    );
    assert!(
        e.contains("zones[1].colour ('east'): with a mask image every zone needs its colour"),
        "{e}"
    );
    let e = run(
        "nofile.json",
        serde_json::json!({"schema": "herdfit.zones/1", "mask": "missing.png", "zones": two("#ff0000", "#0000ff")}),
    );
    assert!(
        e.contains("missing.png") && e.contains("no such file"),
        "{e}"
    );
    let e = run(
        "nomask.json",
        serde_json::json!({"schema": "herdfit.zones/1", "zones": [
            {"name": "west", "colour": "#ff0000", "polygon": rect(0.0, 9.0)},
            {"name": "east", "polygon": rect(9.0, 24.0)}]}),
    );
    assert!(
        e.contains("zones[0].colour ('west'): a colour needs a mask image"),
        "{e}"
    );
}
