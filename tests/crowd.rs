//! The crowd system (Lee et al. 2007): eq. 1 sectors, eq. 2 probabilities, eq. 3 regression,
//! kd-tree against brute force, k-means against linfa, determinism, bad input, the ETH/UCY
//! protocol on one fold and the imitation of herdfit's own herd model.

mod common;

use common::{fails, herdfit, ok, s};
use herdfit::crowd::action::{cluster_probabilities, kmeans, lwr};
use herdfit::crowd::features::{formation, SECTORS};
use herdfit::crowd::knn::{brute_force, KiddoTree, StateTree};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use std::path::{Path, PathBuf};

/// `$HERDFIT_SHARED_DATA`, else `<repo>/../shared/data`, else `/work/shared/data`.
fn shared_data() -> PathBuf {
    if let Some(d) = std::env::var_os("HERDFIT_SHARED_DATA") {
        return PathBuf::from(d);
    }
    let sibling = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if sibling.is_dir() {
        return sibling;
    }
    PathBuf::from("/work/shared/data")
}

#[test]
fn eq1_sectors_on_hand_placed_neighbours() {
    let r = 2.0;
    let f = |d: f64| (r - d) * (r - d) / (r * r);
    // Agent at (1, 1) heading +y: "ahead" is +y, "left" is −x.
    let p = [1.0, 1.0];
    let n = [
        [1.0, 2.0],  // ahead, d = 1 → sector 0
        [1.0, 1.5],  // ahead, nearer: d = 0.5 wins sector 0
        [0.0, 1.0],  // left, d = 1 → sector 2
        [1.0, -0.5], // behind, d = 1.5 → sector 4
        [2.0, 0.0],  // behind-right, d = √2 → sector 5
        [4.0, 1.0],  // right but d = 3 ≥ r → nothing
    ];
    let got = formation(p, [0.0, 1.0], n.iter().copied(), r);
    let mut want = [0.0; SECTORS];
    want[0] = f(0.5);
    want[2] = f(1.0);
    want[4] = f(1.5);
    want[5] = f(2f64.sqrt());
    for (g, w) in got.iter().zip(&want) {
        assert!((g - w).abs() < 1e-12, "{got:?} vs {want:?}");
    }
    assert!((got[0] - 0.5625).abs() < 1e-12, "(2 − 0.5)²/2² = 0.5625");
}

#[test]
fn eq2_probabilities_are_inverse_distances() {
    let m = [[1.0, 0.0], [0.0, 1.0], [3.0, 0.0]];
    let p = cluster_probabilities(&m, [0.0, 0.0]);
    for (g, w) in p.iter().zip([3.0 / 7.0, 3.0 / 7.0, 1.0 / 7.0]) {
        assert!((g - w).abs() < 1e-12, "{p:?}");
    }
    // The previous cluster's mean itself is kept for sure.
    assert_eq!(cluster_probabilities(&m, [3.0, 0.0]), vec![0.0, 0.0, 1.0]);
}

/// Ordinary least squares by modified Gram–Schmidt QR (independent of the normal equations).
fn ols_qr(x: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let (n, m) = (x.len(), x[0].len());
    let mut q: Vec<Vec<f64>> = (0..m).map(|j| (0..n).map(|i| x[i][j]).collect()).collect();
    let mut rr = vec![vec![0.0; m]; m];
    for j in 0..m {
        for k in 0..j {
            let d: f64 = (0..n).map(|i| q[k][i] * q[j][i]).sum();
            rr[k][j] = d;
            let qk = q[k].clone();
            for (v, w) in q[j].iter_mut().zip(&qk) {
                *v -= d * w;
            }
        }
        let norm = q[j].iter().map(|v| v * v).sum::<f64>().sqrt();
        rr[j][j] = norm;
        q[j].iter_mut().for_each(|v| *v /= norm);
    }
    let qty: Vec<f64> = (0..m)
        .map(|j| (0..n).map(|i| q[j][i] * y[i]).sum())
        .collect();
    let mut b = vec![0.0; m];
    for j in (0..m).rev() {
        b[j] = (qty[j] - (j + 1..m).map(|k| rr[j][k] * b[k]).sum::<f64>()) / rr[j][j];
    }
    b
}

#[test]
fn eq3_lwr_is_ols_at_infinite_bandwidth_and_exact_on_linear_data() {
    let mut rng = ChaCha8Rng::seed_from_u64(11);
    let d = 4;
    let q: Vec<f64> = (0..d).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let states: Vec<Vec<f64>> = (0..40)
        .map(|_| (0..d).map(|_| rng.gen_range(-2.0..2.0)).collect())
        .collect();
    let noisy: Vec<[f64; 2]> = states
        .iter()
        .map(|s| [s[0] - 0.5 * s[2] + rng.gen_range(-0.3..0.3), s[1] * s[3]])
        .collect();
    let d2 = |s: &[f64]| {
        s.iter()
            .zip(&q)
            .map(|(a, b)| (a - b) * (a - b))
            .sum::<f64>()
    };
    let rows: Vec<(&[f64], [f64; 2], f64)> = states
        .iter()
        .zip(&noisy)
        .map(|(s, a)| (s.as_slice(), *a, d2(s)))
        .collect();
    let (mut ata, mut atb) = (Vec::new(), Vec::new());
    let got = lwr(&q, &rows, f64::INFINITY, 0.0, &mut ata, &mut atb);
    let design: Vec<Vec<f64>> = states
        .iter()
        .map(|s| std::iter::once(1.0).chain(s.iter().copied()).collect())
        .collect();
    for c in 0..2 {
        let y: Vec<f64> = noisy.iter().map(|a| a[c]).collect();
        let b = ols_qr(&design, &y);
        let pred = b[0] + (0..d).map(|k| b[k + 1] * q[k]).sum::<f64>();
        assert!(
            (got[c] - pred).abs() < 1e-9,
            "axis {c}: {} vs OLS {pred}",
            got[c]
        );
    }
    // A linear function is reproduced exactly at any bandwidth.
    let lin = |s: &[f64]| [0.3 + s[0] - 2.0 * s[1], -1.0 + 0.5 * s[2] + s[3]];
    let exact: Vec<(&[f64], [f64; 2], f64)> = states
        .iter()
        .map(|s| (s.as_slice(), lin(s), d2(s)))
        .collect();
    for h2 in [0.5, 2.0, 50.0] {
        let g = lwr(&q, &exact, h2, 0.0, &mut ata, &mut atb);
        let w = lin(&q);
        assert!(
            (g[0] - w[0]).abs() < 1e-9 && (g[1] - w[1]).abs() < 1e-9,
            "{g:?} {w:?}"
        );
    }
}

#[test]
fn kd_tree_knn_equals_brute_force() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut got_far = Vec::new();
    for dims in [3, 8, 10, 12] {
        let pts: Vec<f64> = (0..5000 * dims)
            .map(|i| rng.gen_range(-1.0..1.0) * (1.0 + (i % dims) as f64))
            .collect();
        let tree = StateTree::build(&pts, dims).unwrap();
        let kiddo = KiddoTree::build(&pts, dims).unwrap();
        let (mut got, mut peer) = (Vec::new(), Vec::new());
        for i in 0..40 {
            // Queries far outside the samples too (a simulated agent in an unseen situation).
            let spread = if i % 4 == 0 { 20.0 } else { 2.0 };
            let q: Vec<f64> = (0..dims)
                .map(|k| rng.gen_range(-spread..spread) * (1.0 + k as f64))
                .collect();
            for k in [1, 5, 100] {
                tree.nearest(&q, k, &mut got);
                kiddo.nearest(&q, k, &mut peer);
                let want = brute_force(&pts, dims, &q, k);
                assert_eq!(got.len(), k);
                assert_eq!(got, want, "dims {dims}, k {k}: the same rows and distances");
                for (g, w) in peer.iter().zip(&want) {
                    assert_eq!(g.1, w.1, "kiddo, dims {dims}");
                    assert!((g.0 - w.0).abs() <= 1e-9 * w.0.max(1.0));
                }
            }
        }
    }
    // Points whose f32 roundings are coarser than their spacing (coordinates near 10⁴, spread
    // 10⁻³; f32 steps there are ≈ 10⁻³): the tree's f32 leaf filter must still pass every
    // candidate, and the exact f64 distances decide, as brute force's do.
    let far: Vec<f64> = (0..3000 * 10)
        .map(|i| 1.0e4 * (1.0 + (i % 10) as f64) + rng.gen_range(-1e-3..1e-3))
        .collect();
    let tree = StateTree::build(&far, 10).unwrap();
    for i in 0..20 {
        let q: Vec<f64> = (0..10)
            .map(|k| 1.0e4 * (1.0 + k as f64) + rng.gen_range(-2e-3..2e-3) * (1 + i % 3) as f64)
            .collect();
        for k in [1, 7, 100] {
            tree.nearest(&q, k, &mut got_far);
            assert_eq!(got_far, brute_force(&far, 10, &q, k), "far points, k {k}");
        }
    }
    // Coordinates near 10³⁹, beyond f32: every point is a candidate and
    // the exact distances decide.
    let huge: Vec<f64> = (0..500 * 4)
        .map(|i| 1.0e39 * (1.0 + (i % 4) as f64) + rng.gen_range(-1e36..1e36))
        .collect();
    let tree = StateTree::build(&huge, 4).unwrap();
    for _ in 0..5 {
        let q: Vec<f64> = (0..4)
            .map(|k| 1.0e39 * (1.0 + k as f64) + rng.gen_range(-2e36..2e36))
            .collect();
        for k in [1, 30, 100] {
            tree.nearest(&q, k, &mut got_far);
            assert_eq!(got_far, brute_force(&huge, 4, &q, k), "huge points, k {k}");
        }
    }
    // Hundreds of copies of one point among the others: many candidates tie at the k-th
    // distance, so the candidate buffer must grow rather than cut them.
    let mut copies: Vec<f64> = (0..2000 * 6).map(|_| rng.gen_range(-1.0..1.0)).collect();
    for i in (0..2000).step_by(4) {
        copies[i * 6..(i + 1) * 6].copy_from_slice(&[0.1, 0.2, 0.3, -0.1, 0.0, 0.5]);
    }
    let tree = StateTree::build(&copies, 6).unwrap();
    for q in [
        [0.1, 0.2, 0.3, -0.1, 0.0, 0.5],
        [0.3, 0.2, 0.1, 0.0, 0.0, 0.4],
    ] {
        for k in [1, 100, 499, 500, 501, 700] {
            tree.nearest(&q, k, &mut got_far);
            assert_eq!(got_far, brute_force(&copies, 6, &q, k), "copies, k {k}");
        }
    }
    // Ties: a lattice with many equal distances; rows of equal distance come in row order.
    let lattice: Vec<f64> = (0..400)
        .flat_map(|i| [(i % 20) as f64, (i / 20) as f64])
        .collect();
    let tree = StateTree::build(&lattice, 2).unwrap();
    let mut got = Vec::new();
    for q in [[5.0, 5.0], [5.5, 5.5], [0.0, 0.0], [-3.0, 30.0]] {
        for k in [4, 9, 37, 400] {
            tree.nearest(&q, k, &mut got);
            assert_eq!(got, brute_force(&lattice, 2, &q, k), "{q:?} {k}");
        }
    }
    // Few samples: one partial leaf, a leaf and one point, fewer leaves than a SIMD row of
    // leaf boxes; k up to beyond the samples.
    for dims in [1, 5] {
        for n in [1, 3, 16, 17, 130] {
            let pts: Vec<f64> = (0..n * dims).map(|_| rng.gen_range(-1.0..1.0)).collect();
            let tree = StateTree::build(&pts, dims).unwrap();
            for _ in 0..5 {
                let q: Vec<f64> = (0..dims).map(|_| rng.gen_range(-1.5..1.5)).collect();
                for k in [1, 2, n, n + 3] {
                    tree.nearest(&q, k, &mut got);
                    assert_eq!(got.len(), k.min(n), "dims {dims}, {n} samples, k {k}");
                    assert_eq!(
                        got,
                        brute_force(&pts, dims, &q, k),
                        "dims {dims}, n {n}, k {k}"
                    );
                }
            }
        }
    }
    // More than the samples: all of them.
    let tree = StateTree::build(&lattice, 2).unwrap();
    tree.nearest(&[1.0, 1.0], 1000, &mut got);
    assert_eq!(got.len(), 400);
    assert!(StateTree::build(&[0.0; 26], 13).is_err());
    assert!(StateTree::build(&[0.0; 26], 0).is_err());
}

#[test]
fn tree_memory_is_linear_in_the_samples() {
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let bytes = |n: usize, rng: &mut ChaCha8Rng| {
        let pts: Vec<f64> = (0..n * 10).map(|_| rng.gen_range(-1.0..1.0)).collect();
        StateTree::build(&pts, 10).unwrap().bytes()
    };
    let (a, b) = (bytes(5000, &mut rng), bytes(20000, &mut rng));
    let per = a as f64 / 5000.0;
    assert!(
        per < 140.0,
        "{per} bytes per 10-D sample (80 for the point, 40 for its f32 copy, ≈ 10 for the boxes)"
    );
    let ratio = b as f64 / a as f64;
    assert!(
        (3.9..4.1).contains(&ratio),
        "4× the samples, {ratio}× the bytes"
    );
}

#[test]
fn kmeans_matches_linfa_on_separated_clusters() {
    use linfa::traits::Fit;
    use linfa::DatasetBase;
    use linfa_clustering::KMeans;
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let centres = [[1.3, 0.0], [0.2, 0.6], [0.9, -0.8]];
    let pts: Vec<[f64; 2]> = (0..99)
        .map(|i| {
            let c = centres[i % 3];
            [
                c[0] + rng.gen_range(-0.1..0.1),
                c[1] + rng.gen_range(-0.1..0.1),
            ]
        })
        .collect();
    let mut assign = Vec::new();
    let ours = kmeans(&pts, 3, 20, &mut rng, &mut assign);
    assert_eq!(ours.len(), 3);
    let data = ndarray016::Array2::from_shape_fn((pts.len(), 2), |(i, j)| pts[i][j]);
    let model = KMeans::params_with_rng(3, ChaCha8Rng::seed_from_u64(1))
        .fit(&DatasetBase::from(data.clone()))
        .unwrap();
    use linfa::traits::Predict;
    let theirs = model.predict(&data);
    // Same partition up to the cluster labels.
    for i in 0..pts.len() {
        for j in 0..pts.len() {
            assert_eq!(assign[i] == assign[j], theirs[i] == theirs[j], "{i} {j}");
        }
    }
}

fn synth(dir: &Path, name: &str, seed: u64, secs: f64) -> PathBuf {
    let p = dir.join(name);
    ok(&[
        "crowd",
        "synth",
        "--seed",
        &seed.to_string(),
        "--duration",
        &secs.to_string(),
        "--out",
        s(&p),
    ]);
    p
}

#[test]
fn simulation_bytes_depend_on_seed_not_threads() {
    let dir = tempfile::tempdir().unwrap();
    let src = synth(dir.path(), "corridor.csv", 3, 40.0);
    let model = dir.path().join("model.json");
    ok(&[
        "crowd",
        "learn",
        s(&src),
        "--max-samples",
        "3000",
        "--out",
        s(&model),
    ]);
    let run = |name: &str, seed: &str, threads: &str| {
        let out = dir.path().join(name);
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_herdfit"))
            .env("RAYON_NUM_THREADS", threads)
            .args([
                "crowd",
                "simulate",
                s(&model),
                "--entries",
                s(&src),
                "--seed",
                seed,
                "--out",
                s(&out),
            ])
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        std::fs::read(&out).unwrap()
    };
    let a = run("a.csv", "5", "1");
    let b = run("b.csv", "5", "2");
    let c = run("c.csv", "6", "2");
    assert!(a.len() > 10_000);
    assert_eq!(a, b, "same seed, 1 vs 2 threads");
    assert_ne!(a, c, "another seed draws other clusters");
    // The model file round-trips to the same bytes.
    let again = dir.path().join("again.json");
    ok(&[
        "crowd",
        "learn",
        s(&src),
        "--max-samples",
        "3000",
        "--out",
        s(&again),
    ]);
    assert_eq!(
        std::fs::read(&model).unwrap(),
        std::fs::read(&again).unwrap()
    );
}

#[test]
fn bad_input_gets_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let write = |name: &str, text: &str| {
        let p = d.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let out = d.join("model.json");
    let one = write(
        "one.csv",
        "frame,time,id,x,y\n0,0,1,0,0\n1,0.4,1,1,0\n2,0.8,1,2,0\n",
    );
    let e = fails(&["crowd", "learn", s(&one), "--out", s(&out)]);
    assert!(e.contains("one.csv") && e.contains("1 individual"), "{e}");
    let dup = write(
        "dup.csv",
        "frame,time,id,x,y\n0,0,1,0,0\n0,0,1,1,0\n1,0.4,2,2,0\n",
    );
    let e = fails(&["crowd", "learn", s(&dup), "--out", s(&out)]);
    assert!(
        e.contains("dup.csv") && e.contains("duplicate (frame, id)"),
        "{e}"
    );
    let back = write(
        "back.csv",
        "frame,time,id,x,y\n0,0,1,0,0\n0,0,2,1,0\n1,0,1,2,0\n1,0,2,3,0\n",
    );
    let e = fails(&["crowd", "learn", s(&back), "--out", s(&out)]);
    assert!(
        e.contains("back.csv") && e.contains("does not increase"),
        "{e}"
    );
    assert!(!out.exists());
    // A step inertia outside [0, 1].
    let src = synth(d, "c.csv", 1, 30.0);
    let bad = write("bad.json", r#"{"action": {"inertia": 1.5}}"#);
    let e = fails(&[
        "crowd",
        "learn",
        s(&src),
        "--config",
        s(&bad),
        "--out",
        s(&out),
    ]);
    assert!(e.contains("action.inertia") && e.contains("[0, 1]"), "{e}");
    assert!(!out.exists());
    // A layout polygon with two points.
    ok(&[
        "crowd",
        "learn",
        s(&src),
        "--max-samples",
        "2000",
        "--out",
        s(&out),
    ]);
    let lay = write(
        "layout.json",
        r#"{"schema": "herdfit.crowd-layout/1", "obstacles": [[[0, 0], [1, 1]]],
            "spawns": [{"position": [0, 1], "goal": [10, 1], "count": 3}]}"#,
    );
    let sim = d.join("sim.csv");
    let e = fails(&[
        "crowd",
        "simulate",
        s(&out),
        "--layout",
        s(&lay),
        "--out",
        s(&sim),
    ]);
    assert!(
        e.contains("layout.json") && e.contains("obstacles[0]") && e.contains("at least 3 points"),
        "{e}"
    );
    // A line region whose join probability is not a probability.
    let lay2 = write(
        "layout2.json",
        r#"{"schema": "herdfit.crowd-layout/1", "pivots": [{"name": "b", "position": [5, 5],
            "orientation_deg": 90}], "regions": [{"behaviour": "line", "pivot": "b", "join": 1.5,
            "polygon": [[4, 2], [6, 2], [6, 6], [4, 6]]}],
            "spawns": [{"position": [0, 1], "goal": [10, 1], "count": 3}]}"#,
    );
    let e = fails(&[
        "crowd",
        "simulate",
        s(&out),
        "--layout",
        s(&lay2),
        "--out",
        s(&sim),
    ]);
    assert!(
        e.contains("layout2.json") && e.contains("regions[0].join = 1.5"),
        "{e}"
    );
    let e = fails(&[
        "crowd",
        "learn",
        s(&src),
        "--k",
        "0",
        "--out",
        s(&d.join("m2.json")),
    ]);
    // The flag that set the key, not the key (issue #47).
    assert!(e.contains("--k") && !e.contains("action.k"), "{e}");
    let names: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        !names
            .iter()
            .any(|n| n.starts_with("sim") || n.starts_with("m2") || n.starts_with(".herdfit")),
        "{names:?}"
    );
}

#[test]
fn layout_simulation_forms_a_line_and_writes_a_picture() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let src = synth(d, "c.csv", 2, 60.0);
    let model = d.join("m.json");
    ok(&[
        "crowd",
        "learn",
        s(&src),
        "--max-samples",
        "5000",
        "--out",
        s(&model),
    ]);
    let lay = d.join("hall-layout.json");
    herdfit::crowd::demo_layout().save(&lay).unwrap();
    let (out, png) = (d.join("hall.csv"), d.join("hall.png"));
    let text = ok(&[
        "crowd",
        "simulate",
        s(&model),
        "--layout",
        s(&lay),
        "--png",
        s(&png),
        "--out",
        s(&out),
    ]);
    assert!(text.contains("80 agents"), "{text}");
    // Most walk through the hall to their exits; about 30 % (the region's `join`) queue.
    let count = |what: &str| -> usize {
        let at = text.find(what).unwrap_or_else(|| panic!("{what}: {text}"));
        text[..at]
            .split_whitespace()
            .last()
            .unwrap()
            .parse()
            .unwrap()
    };
    assert!(count(" arrived") >= 40, "{text}");
    assert!((8..=40).contains(&count(" joined a line")), "{text}");
    let t = herdfit::data::tracks::Tracks::load(&out).unwrap();
    let roles: std::collections::BTreeSet<&str> =
        t.rows.iter().filter_map(|r| r.role.as_deref()).collect();
    assert!(
        roles.contains("line") && roles.contains("locomotion"),
        "{roles:?}"
    );
    // A line forms: in some frame at least four queueing agents stand on the places behind the
    // booth (22, 9), 0.8 m apart along −y, each within 0.1 m of one.
    let on_place = |p: [f64; 3]| {
        let r = ((9.0 - p[1]) / 0.8).round();
        r >= 0.0 && (p[0] - 22.0).hypot(p[1] - (9.0 - 0.8 * r)) < 0.1
    };
    let mut standing: std::collections::BTreeMap<u64, usize> = Default::default();
    for r in t.rows.iter().filter(|r| r.role.as_deref() == Some("line")) {
        *standing.entry(r.frame).or_default() += usize::from(on_place(r.pos));
    }
    let most = standing.values().copied().max().unwrap_or(0);
    assert!(most >= 4, "at most {most} agents in line on their places");
    // Nobody steps through the walls at y = 0 and y = 10 (segments from x = 0 to 30; the hall's
    // ends are open, so an agent may walk out and round a wall's end) or into the pillar.
    let cross = |p: [f64; 3], q: [f64; 3], y: f64| {
        let (a, b) = (p[1] - y, q[1] - y);
        if a * b > 0.0 || a == b {
            return false;
        }
        let x = p[0] + (q[0] - p[0]) * a / (a - b);
        (0.0..=30.0).contains(&x)
    };
    let mut last: std::collections::BTreeMap<u64, [f64; 3]> = Default::default();
    for r in &t.rows {
        assert!(
            !(r.pos[0] > 14.0 && r.pos[0] < 16.0 && r.pos[1] > 4.0 && r.pos[1] < 6.0),
            "{r:?}"
        );
        if let Some(p) = last.insert(r.id, r.pos) {
            assert!(
                !cross(p, r.pos, 0.0) && !cross(p, r.pos, 10.0),
                "{p:?} → {r:?}"
            );
        }
    }
    // The minimum-distance correction (0.3 m) leaves no pair of agents closer than the 0.2 m
    // that counts as a collision.
    let mut by_frame: std::collections::BTreeMap<u64, Vec<[f64; 3]>> = Default::default();
    for r in &t.rows {
        by_frame.entry(r.frame).or_default().push(r.pos);
    }
    for (f, ps) in &by_frame {
        for (i, p) in ps.iter().enumerate() {
            for q in &ps[i + 1..] {
                assert!(
                    (p[0] - q[0]).hypot(p[1] - q[1]) >= 0.2,
                    "frame {f}: {p:?} {q:?}"
                );
            }
        }
    }
    assert!(std::fs::metadata(&png).unwrap().len() > 10_000);
}

/// Leave-one-scene-out on HOTEL: the constant-velocity baseline reproduces the data README's
/// figures (0.32/0.61) and the learnt model beats it.
#[test]
fn eth_ucy_hotel_fold_beats_constant_velocity() {
    let data = shared_data().join("pedestrians/eth-ucy");
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("eval.json");
    // Two candidates (the full default grid is measured in RESULTS.md §4; this keeps the test
    // short): chosen inside the training scenes, never on HOTEL.
    let tuning = dir.path().join("tuning.json");
    std::fs::write(
        &tuning,
        r#"{"smoothing": [3], "formation": [0], "bandwidth_scale": [1, 3]}"#,
    )
    .unwrap();
    let text = ok(&[
        "crowd",
        "evaluate",
        "--data",
        s(&data),
        "--scene",
        "HOTEL",
        "--tuning",
        s(&tuning),
        "--json",
        s(&json),
    ]);
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(rep["schema"], "herdfit.crowd-eval/1");
    let f = &rep["folds"][0];
    let g = |a: &str, b: &str| f[a][b].as_f64().unwrap();
    assert!(
        (g("constant_velocity", "ade") - 0.32).abs() < 0.005,
        "{text}"
    );
    assert!(
        (g("constant_velocity", "fde") - 0.61).abs() < 0.005,
        "{text}"
    );
    assert!(f["windows"].as_u64().unwrap() > 1000, "{text}");
    assert!(g("model", "ade") < g("constant_velocity", "ade"), "{text}");
    assert!(g("model", "fde") < g("constant_velocity", "fde"), "{text}");
    assert_eq!(f["candidates"].as_array().unwrap().len(), 2, "{text}");
    assert!(f["chosen"].as_u64().unwrap() < 2, "{text}");
    // The rollout's collision rate is no higher than the data's (0.2 m; RESULTS.md §4).
    assert!(
        g("model", "collision_rate") <= f["data_collision_rate"].as_f64().unwrap(),
        "{text}"
    );
}

/// All five leave-one-scene-out folds with the default nested tuning: the learnt model beats
/// constant velocity on the scene-averaged ADE and FDE by a margin (measured 0.519/1.076 against
/// 0.534/1.148, RESULTS.md §4), and its rollouts collide no more often than the data.
#[test]
fn eth_ucy_five_folds_beat_constant_velocity_on_average() {
    let data = shared_data().join("pedestrians/eth-ucy");
    let dir = tempfile::tempdir().unwrap();
    let json = dir.path().join("eval.json");
    let text = ok(&["crowd", "evaluate", "--data", s(&data), "--json", s(&json)]);
    let rep: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(rep["folds"].as_array().unwrap().len(), 5, "{text}");
    let a = &rep["average"];
    let g = |x: &str, y: &str| a[x][y].as_f64().unwrap();
    assert!(
        (g("constant_velocity", "ade") - 0.534).abs() < 0.001,
        "{text}"
    );
    assert!(
        g("model", "ade") < 0.98 * g("constant_velocity", "ade"),
        "{text}"
    );
    assert!(
        g("model", "fde") < 0.96 * g("constant_velocity", "fde"),
        "{text}"
    );
    assert!(
        g("model", "collision_rate") <= a["data_collision_rate"].as_f64().unwrap(),
        "{text}"
    );
}

#[test]
fn crowd_help_lists_the_verbs() {
    let o = herdfit(&["crowd", "--help"]);
    let t = String::from_utf8_lossy(&o.stdout);
    for v in ["learn", "simulate", "evaluate", "compare", "synth"] {
        assert!(t.contains(v), "{t}");
    }
}
