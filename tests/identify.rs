//! Identifiability at the fitted point (issue #15 item 2): the estimator on toy objectives whose
//! curvature and gradient noise are known analytically (a 2-parameter quadratic, a degenerate one
//! with a flat direction, a minimum outside the box), then the `uncertainty` of a real fit: in the
//! file, round-tripping, deterministic, absent with `--no-uncertainty` (the bytes of the fit
//! without it), printed by `fit` and shown by `validate`.

mod common;
use common::{ok, s};
use herdfit::herd::params::Params;
use herdfit::optim::curvature::{check, estimate, Estimate, Settings, Window, S_MAX};
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, StandardNormal};
use std::path::Path;

/// A quadratic objective ½ (x − m)ᵀ A (x − m) observed through `n` windows whose gradients carry
/// independent noise L z (z standard normal, drawn from the seed alone: common random numbers),
/// plus optional noise that also depends on x (`jitter`: breaks the common random numbers).
struct Toy {
    a: DMatrix<f64>,
    m: DVector<f64>,
    l: DMatrix<f64>,
    n: usize,
    jitter: f64,
    replicate: u64,
}

impl Toy {
    fn probe(&self, x: &[f64], seed: usize) -> Result<Vec<Window>, ()> {
        let mut rng = ChaCha8Rng::seed_from_u64(self.replicate * 1000 + seed as u64);
        let bits = x.iter().fold(0u64, |h, v| h.rotate_left(7) ^ v.to_bits());
        let mut other = ChaCha8Rng::seed_from_u64(bits ^ seed as u64);
        let d = DVector::from_column_slice(x) - &self.m;
        let g0 = &self.a * &d;
        let l0 = 0.5 * (d.transpose() * &self.a * &d)[(0, 0)];
        Ok((0..self.n)
            .map(|_| {
                let z = DVector::from_fn(x.len(), |_, _| StandardNormal.sample(&mut rng));
                let e = DVector::from_fn(x.len(), |_, _| {
                    let v: f64 = StandardNormal.sample(&mut other);
                    v * self.jitter
                });
                let g = &g0 + &self.l * z + e;
                let noise: f64 = StandardNormal.sample(&mut rng);
                (l0 + 0.1 * noise, g.iter().copied().collect())
            })
            .collect())
    }

    fn run(&self, x: &[f64], s: &Settings) -> Estimate {
        estimate(x, &[0.0; 2], &[1.0; 2], s, |p, seed| self.probe(p, seed)).unwrap()
    }
}

fn rotation(deg: f64) -> DMatrix<f64> {
    let (c, s) = (deg.to_radians().cos(), deg.to_radians().sin());
    DMatrix::from_row_slice(2, 2, &[c, -s, s, c])
}

fn settings(seeds: usize, batches: usize) -> Settings {
    Settings {
        step: 0.05,
        seeds,
        batches,
        accuracy: 0.06,
        bound_tol: 0.005,
    }
}

/// A = R diag(4, 1) Rᵀ (R a 30° rotation), gradient noise Σ_ε = L Lᵀ with L = diag(0.4, 0.25):
/// the curvature comes out exactly (a quadratic under common random numbers), the eigen-directions
/// are R's columns, and the standard deviations are √diag(A⁻¹ Σ_ε A⁻¹ / (S n)) within 15 % (the
/// batch-means variance from 200 batches has a relative spread of about 5 % in the std).
#[test]
fn a_quadratic_with_known_curvature_and_noise_is_recovered() {
    let r = rotation(30.0);
    let a = &r * DMatrix::from_diagonal(&DVector::from_vec(vec![4.0, 1.0])) * r.transpose();
    let l = DMatrix::from_diagonal(&DVector::from_vec(vec![0.4, 0.25]));
    let toy = Toy {
        a: a.clone(),
        m: DVector::from_vec(vec![0.5, 0.4]),
        l: l.clone(),
        n: 2000,
        jitter: 0.0,
        replicate: 1,
    };
    let s = settings(2, 200);
    let est = toy.run(&[0.52, 0.37], &s);
    assert_eq!(est.windows, 2000);
    assert_eq!(est.batches, 200);
    for i in 0..2 {
        for j in 0..2 {
            assert!(
                (est.hessian[i][j] - a[(i, j)]).abs() < 1e-9,
                "{:?}",
                est.hessian
            );
        }
    }
    assert_eq!(est.directions.len(), 2);
    for (k, want) in [(0, 4.0), (1, 1.0)] {
        let d = &est.directions[k];
        assert!((d.eigenvalue - want).abs() < 1e-9, "{}", d.eigenvalue);
        assert!(d.eigenvalue_std < 1e-9, "exact under common random numbers");
        let v = r.column(k);
        let dot = (d.vector[0] * v[0] + d.vector[1] * v[1]).abs();
        assert!(dot > 1.0 - 1e-9, "direction {k}: {:?} vs {v}", d.vector);
        assert!(d.determined);
        // The minimum along the direction: vᵀ(m − x) up to the noise (≤ 3 std).
        let to = (0.5 - 0.52) * d.vector[0] + (0.4 - 0.37) * d.vector[1];
        let got = d.to_minimum.unwrap();
        assert!((got - to).abs() < 3.0 * d.std.unwrap(), "{got} vs {to}");
    }
    let ai = a.clone().try_inverse().unwrap();
    let cov = &ai * (&l * l.transpose()) * &ai / (2.0 * 2000.0);
    for i in 0..2 {
        let want = cov[(i, i)].sqrt();
        let got = est.std[i].unwrap();
        assert!((got / want - 1.0).abs() < 0.15, "std {i}: {got} vs {want}");
        assert!(est.determined[i] && est.bound[i].is_none());
    }
    // Along each direction: √(vᵀ Σ_ε v / (S n)) / λ.
    for (k, lam) in [(0, 4.0), (1, 1.0)] {
        let v = r.column(k);
        let want = ((v.transpose() * (&l * l.transpose()) * v)[(0, 0)] / 4000.0).sqrt() / lam;
        let got = est.directions[k].std.unwrap();
        assert!(
            (got / want - 1.0).abs() < 0.15,
            "direction {k}: {got} vs {want}"
        );
    }
}

/// The reported standard deviations are honest: over 200 replicates of the noise, the minimiser
/// of each replicate's estimated objective (m + A⁻¹ ε̄, what a fit would find) lies within 2 of
/// its replicate's std of the true minimum m in at least 90 % of the 400 parameter × replicate
/// cases (95.4 % expected for a normal estimate), and not in all of them (the std is not inflated).
#[test]
fn the_standard_errors_cover_the_true_minimum() {
    let r = rotation(-50.0);
    let a = &r * DMatrix::from_diagonal(&DVector::from_vec(vec![2.0, 0.5])) * r.transpose();
    let l = DMatrix::from_row_slice(2, 2, &[0.3, 0.0, 0.1, 0.2]);
    let m = DVector::from_vec(vec![0.45, 0.6]);
    let s = settings(2, 20);
    let (mut covered, mut total) = (0, 0);
    for rep in 0..200 {
        let toy = Toy {
            a: a.clone(),
            m: m.clone(),
            l: l.clone(),
            n: 200,
            jitter: 0.0,
            replicate: 100 + rep,
        };
        // The replicate's fitted point: where its estimated mean gradient vanishes.
        let at_m = toy.run(m.as_slice(), &s);
        let g = DVector::from_vec(at_m.gradient.clone());
        let fitted = &m - a.clone().try_inverse().unwrap() * g;
        let est = toy.run(fitted.as_slice(), &s);
        for i in 0..2 {
            total += 1;
            if (fitted[i] - m[i]).abs() <= 2.0 * est.std[i].unwrap() {
                covered += 1;
            }
        }
    }
    let rate = covered as f64 / total as f64;
    eprintln!("coverage of the true minimum: {covered} of {total}");
    assert!((0.9..0.995).contains(&rate), "coverage {rate}");
}

/// A = 3 u uᵀ with u = (1, −1)/√2: flat along (1, 1)/√2, where only noise that breaks the common
/// random numbers gives the differences anything. The flat direction is reported undetermined
/// (no std), the stiff one determined with its eigenvalue, and each parameter's std is at least
/// the uniform spread over √2 (each has weight ½ on the flat direction: std ≥ S_MAX/√2, less 5 %
/// for the estimated direction's tilt).
#[test]
fn a_flat_direction_is_reported_undetermined() {
    let u = DVector::from_vec(vec![1.0, -1.0]) / 2f64.sqrt();
    let toy = Toy {
        a: &u * u.transpose() * 3.0,
        m: DVector::from_vec(vec![0.5, 0.5]),
        l: DMatrix::from_diagonal(&DVector::from_vec(vec![0.3, 0.3])),
        n: 400,
        jitter: 0.5,
        replicate: 7,
    };
    let est = toy.run(&[0.5, 0.5], &settings(4, 20));
    let (stiff, flat) = (&est.directions[0], &est.directions[1]);
    assert!((stiff.eigenvalue - 3.0).abs() < 0.2, "{}", stiff.eigenvalue);
    assert!(stiff.determined && stiff.std.is_some());
    assert!((stiff.vector[0] - u[0]).abs() < 0.05 || (stiff.vector[0] + u[0]).abs() < 0.05);
    assert!(
        flat.eigenvalue.abs() < 3.0 * flat.eigenvalue_std + 1e-12,
        "{flat:?}"
    );
    assert!(!flat.determined && flat.std.is_none(), "{flat:?}");
    for i in 0..2 {
        let sd = est.std[i].unwrap();
        assert!(sd >= 0.95 * S_MAX / 2f64.sqrt(), "std {i} = {sd}");
        assert!(!est.determined[i]);
    }
}

/// The minimum lies outside the box (m₀ = −0.1, A = 2 I): the estimate held at the lower bound
/// gets no std but a one-sided interval [0, (ḡ + 2σ)/c] with the one-sided curvature c = 2 and
/// ḡ ≈ 0.2; the free parameter keeps its two-sided std.
#[test]
fn a_parameter_at_a_bound_gets_a_one_sided_interval() {
    let toy = Toy {
        a: DMatrix::identity(2, 2) * 2.0,
        m: DVector::from_vec(vec![-0.1, 0.5]),
        l: DMatrix::identity(2, 2) * 0.2,
        n: 500,
        jitter: 0.0,
        replicate: 3,
    };
    let est = toy.run(&[0.0, 0.5], &settings(2, 25));
    assert!(est.std[0].is_none() && !est.determined[0]);
    let b = est.bound[0].as_ref().unwrap();
    assert!(!b.upper);
    assert!((est.hessian[0][0] - 2.0).abs() < 1e-9);
    let want = (est.gradient[0] + 2.0 * est.gradient_std[0]) / 2.0;
    assert_eq!(b.within[0], 0.0);
    assert!((b.within[1] - want).abs() < 1e-12, "{b:?} vs {want}");
    assert!((0.1..0.13).contains(&b.within[1]), "{b:?}");
    assert_eq!(est.directions.len(), 1, "only the free parameter");
    assert!(est.std[1].unwrap() < 0.01 && est.determined[1]);
    // One window: no batches to measure the noise with, so nothing is determined.
    let one = Toy { n: 1, ..toy };
    let est = one.run(&[0.3, 0.5], &settings(2, 25));
    assert_eq!(est.batches, 1);
    assert!(est.determined.iter().all(|d| !d), "{:?}", est.std);
    assert!(est
        .directions
        .iter()
        .all(|d| d.std.is_none() && !d.determined));
    let mut bad = settings(1, 25);
    assert_eq!(check(&bad).unwrap_err().0, "seeds");
    bad = settings(2, 25);
    bad.step = f64::NAN;
    assert_eq!(check(&bad).unwrap_err().0, "step");
}

fn make_clip(dir: &Path) -> std::path::PathBuf {
    let out = dir.join("clip");
    ok(&[
        "synth",
        "--agents",
        "80",
        "--frames",
        "17",
        "--grid",
        "8x6",
        "--cell-size",
        "3",
        "--seed",
        "5",
        "--out",
        s(&out),
    ]);
    out
}

/// A fit writes `uncertainty` (std for all 12 parameters or a bound, directions over the free
/// ones, the noise), the file round-trips to the same bytes, two runs give the same bytes, the
/// summary is printed, `--no-uncertainty` writes the same file minus the field, and `validate`
/// shows the section.
#[test]
fn a_fit_writes_prints_and_validates_its_uncertainty() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = make_clip(d);
    let fit = |out: &str, extra: &[&str]| {
        let o = d.join(out);
        let mut a = vec![
            "fit",
            s(&clip),
            "--out",
            s(&o),
            "--epochs",
            "2",
            "--window",
            "4",
        ];
        a.extend_from_slice(extra);
        let printed = ok(&a);
        (o, printed)
    };
    let (a, printed) = fit("a.json", &[]);
    let (b, _) = fit("b.json", &[]);
    let (c, _) = fit("c.json", &["--no-uncertainty"]);
    let bytes = |p: &Path| std::fs::read(p).unwrap();
    assert_eq!(bytes(&a), bytes(&b), "deterministic");
    let p = Params::load(&a).unwrap();
    let u = p.uncertainty.clone().expect("the field is written");
    assert_eq!(u.std.0.len(), 12);
    assert_eq!(u.noise.windows, 4, "16 steps in windows of 4");
    assert_eq!(u.noise.seeds, 2);
    let free = u.std.0.iter().filter(|(_, v)| v.is_some()).count();
    assert_eq!(free + u.bounds.0.len(), 12);
    assert_eq!(u.directions.len(), free);
    for (n, sd) in &u.std.0 {
        assert!(sd.is_some() != u.bounds.get(n).is_some(), "{n}");
        if let Some(x) = sd {
            assert!(x.is_finite() && *x > 0.0 && *x <= S_MAX + 1e-9, "{n}: {x}");
        }
    }
    assert!(
        printed.contains("identifiability at the fitted point"),
        "{printed}"
    );
    assert!(printed.contains("directions determined"), "{printed}");
    // Round trip: load and save again gives the same bytes.
    let again = d.join("again.json");
    p.save(&again).unwrap();
    assert_eq!(bytes(&a), bytes(&again));
    // Without the estimate: the same file minus the field (the fit itself is untouched).
    let text = String::from_utf8(bytes(&c)).unwrap();
    assert!(!text.contains("uncertainty"));
    let mut stripped = p.clone();
    stripped.uncertainty = None;
    let s2 = d.join("stripped.json");
    stripped.save(&s2).unwrap();
    assert_eq!(bytes(&c), bytes(&s2));
    // validate shows it.
    let rep = d.join("report");
    ok(&[
        "validate",
        s(&clip),
        "--params",
        s(&a),
        "--out",
        s(&rep),
        "--seeds",
        "1",
        "--no-video",
    ]);
    let md = std::fs::read_to_string(rep.join("report.md")).unwrap();
    assert!(
        md.contains("What the fitting clip determines (fitted)"),
        "{md}"
    );
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rep.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        json["sets"][0]["uncertainty"]["std"]
            .as_object()
            .unwrap()
            .len(),
        12
    );
    // A bad setting names its flag.
    let o = common::herdfit(&[
        "fit",
        s(&clip),
        "--out",
        s(&d.join("x.json")),
        "--uncertainty-seeds",
        "1",
    ]);
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("--uncertainty-seeds"), "{err}");
    assert!(!d.join("x.json").exists());
}
