//! The herd model on hand-made herds of 2–4 agents: forces against hand-computed values, the
//! leader rule, bearings at φ = 0 and φ = π, and exact replay. All tests here run in f64.

use herdfit::backend::{cpu_device, Compute, Precision};
use herdfit::data::agents::AgentRow;
use herdfit::herd::params::Params;
use herdfit::herd::sim::{
    read_vec, theta_tensor, Decide, ForceTensors, Guidance, HerdState, Model, Recording, World,
};
use herdfit_kernels::ObstacleMap;
use rand::SeedableRng;
use std::f64::consts::PI;

fn device() -> burn::tensor::Device {
    cpu_device(Precision::F64).unwrap()
}

fn agent(id: u64, x: f64, y: f64, hx: f64, hy: f64) -> AgentRow {
    AgentRow {
        id,
        x,
        y,
        vx: hx,
        vy: hy,
    }
}

/// Parameters with only force `g` switched on (weight 1), radial `r`, angular `a`.
fn only(g: usize, r: f64, a: f64) -> Params {
    let mut v = [0.0; 12];
    for f in 0..4 {
        v[3 * f + 1] = 0.5;
        v[3 * f + 2] = 0.5;
    }
    v[3 * g] = 1.0;
    v[3 * g + 1] = r;
    v[3 * g + 2] = a;
    let mut p = Params::default().with_vec(&v);
    p.constants.occlusion = false;
    p
}

fn model(params: Params, world: World) -> Model {
    Model {
        params,
        world,
        dt: 0.04,
        force_kernel: herdfit::herd::sim::ForceKernel::default(),
    }
}

/// Total force on every agent (x, y) at the current state.
fn forces(m: &Model, rows: &[AgentRow]) -> Vec<[f64; 2]> {
    let dev = device();
    let s = HerdState::from_rows(rows, &dev);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let dec = m.decide(&s.snapshot().unwrap(), &mut rng);
    let f = ForceTensors::new(&theta_tensor(&m.params.to_vec(), &dev), &m.params.constants);
    let (fx, fy) = m.forces(&f, &s, &dec);
    let n = rows.len();
    let fx = read_vec(&fx.reshape([n])).unwrap();
    let fy = read_vec(&fy.reshape([n])).unwrap();
    fx.into_iter().zip(fy).map(|(a, b)| [a, b]).collect()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * (1.0 + b.abs())
}

/// Ω · exp(−½ d²/R²) · exp(−½ φ²/Φ²) for normalised r, a (eq. 3–4, R_perc = 4, Ω = 10).
fn gauss(d: f64, phi: f64, r: f64, a: f64) -> f64 {
    let (rr, pp) = (r * 4.0, a * PI);
    10.0 * (-0.5 * d * d / (rr * rr)).exp() * (-0.5 * phi * phi / (pp * pp)).exp()
}

#[test]
fn cohesion_pulls_towards_the_neighbour_with_gaussian_falloff() {
    let m = model(only(0, 0.5, 0.5), World::open());
    // Neighbour 2 BL straight ahead: φ = 0.
    let f = forces(
        &m,
        &[agent(0, 0.0, 0.0, 1.0, 0.0), agent(1, 2.0, 0.0, 1.0, 0.0)],
    );
    let want = gauss(2.0, 0.0, 0.5, 0.5) * 2.0;
    assert!(close(f[0][0], want) && f[0][1] == 0.0, "{f:?} vs {want}");
    // Agent 1 sees agent 0 straight behind (φ = π) and is pulled back.
    let want1 = -gauss(2.0, PI, 0.5, 0.5) * 2.0;
    assert!(close(f[1][0], want1), "{} vs {want1}", f[1][0]);
    // Radial fall-off: at 3 BL the pull is exp(−½(9−4)/R²)·3/2 times as strong.
    let f3 = forces(
        &m,
        &[agent(0, 0.0, 0.0, 1.0, 0.0), agent(1, 3.0, 0.0, 1.0, 0.0)],
    );
    let ratio = f3[0][0] / f[0][0];
    assert!(close(ratio, (-0.5 * 5.0 / 4.0f64).exp() * 1.5), "{ratio}");
    // Angular fall-off: a neighbour at 90° (2 BL to the left) pulls along +y with WA(π/2).
    let f90 = forces(
        &m,
        &[agent(0, 0.0, 0.0, 1.0, 0.0), agent(1, 0.0, 2.0, 1.0, 0.0)],
    );
    let want = gauss(2.0, PI / 2.0, 0.5, 0.5) * 2.0;
    assert!(f90[0][0].abs() < 1e-15 && close(f90[0][1], want), "{f90:?}");
}

#[test]
fn avoidance_pushes_away_with_gaussian_falloff() {
    let m = model(only(1, 0.25, 0.8), World::open());
    let f = forces(
        &m,
        &[agent(0, 0.0, 0.0, 0.0, 1.0), agent(1, 0.0, 1.5, 0.0, 1.0)],
    );
    let want = -gauss(1.5, 0.0, 0.25, 0.8) * 1.5;
    assert!(
        f[0][0].abs() < 1e-15 && close(f[0][1], want),
        "{f:?} vs {want}"
    );
    // Neighbour at 45° front-right, 1 BL away: push along −(offset), weight WR·WA(π/4).
    let s = 1.0 / 2f64.sqrt();
    let f = forces(
        &m,
        &[agent(0, 0.0, 0.0, 0.0, 1.0), agent(1, s, s, 0.0, 1.0)],
    );
    let w = gauss(1.0, PI / 4.0, 0.25, 0.8);
    assert!(close(f[0][0], -w * s) && close(f[0][1], -w * s), "{f:?}");
}

#[test]
fn alignment_turns_towards_neighbour_headings() {
    let m = model(only(2, 0.6, 0.5), World::open());
    // Three agents: the focal one heads +x, neighbours at 2 BL ahead and 2 BL to the left head +y.
    let rows = [
        agent(0, 0.0, 0.0, 1.0, 0.0),
        agent(1, 2.0, 0.0, 0.0, 1.0),
        agent(2, 0.0, 2.0, 0.0, 1.0),
    ];
    let f = forces(&m, &rows);
    let want = gauss(2.0, 0.0, 0.6, 0.5) + gauss(2.0, PI / 2.0, 0.6, 0.5);
    assert!(
        f[0][0].abs() < 1e-15 && close(f[0][1], want),
        "{f:?} vs {want}"
    );
}

#[test]
fn obstacle_points_push_away() {
    let mut map = ObstacleMap::empty([0.0, 0.0], 1.0, 10, 10);
    map.blocked[2 * 10 + 5] = true; // cell centre (5.5, 2.5)
    let world = World {
        obstacles: Some(map),
        guidance: Guidance::None,
        fixed_speed: None,
    };
    let m = model(only(3, 0.5, 0.5), world);
    let f = forces(
        &m,
        &[agent(0, 3.5, 2.5, 1.0, 0.0), agent(1, 3.5, 8.5, 1.0, 0.0)],
    );
    let want = -gauss(2.0, 0.0, 0.5, 0.5) * 2.0;
    assert!(
        close(f[0][0], want) && f[0][1].abs() < 1e-15,
        "{f:?} vs {want}"
    );
    // Agent 1 is 6 BL away: out of range.
    assert_eq!(f[1], [0.0, 0.0]);
}

#[test]
fn weights_and_gradients_are_finite_at_zero_and_pi() {
    let dev = device().autodiff();
    let mut p = Params::default();
    p.constants.occlusion = false;
    // Agent 1 straight ahead of 0 (φ = 0), agent 0 straight behind 1 (φ = π); agent 2 isolated,
    // so its list is all padding.
    let rows = [
        agent(0, 0.0, 0.0, 1.0, 0.0),
        agent(1, 1.0, 0.0, 1.0, 0.0),
        agent(2, 50.0, 50.0, 1.0, 0.0),
    ];
    let m = model(p, World::open());
    let s = HerdState::from_rows(&rows, &dev);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let theta = theta_tensor(&m.params.to_vec(), &dev).require_grad();
    let end = m
        .rollout(
            &theta,
            s,
            3,
            Decide::Live {
                rng: &mut rng,
                record: None,
            },
            |_, d, _| {
                assert_eq!(
                    d.perception
                        .neighbour_mask
                        .iter()
                        .filter(|&&b| b == 1)
                        .count(),
                    2
                );
                Ok(())
            },
        )
        .unwrap();
    let j = (end.x.clone() + end.hy.clone()).sum();
    let grads = j.backward();
    let g = read_vec(&theta.grad(&grads).unwrap()).unwrap();
    assert!(g.iter().all(|v| v.is_finite()), "{g:?}");
    // Cohesion and avoidance act along x on agents 0 and 1: their weights get a gradient.
    assert!(g[0] != 0.0 && g[3] != 0.0, "{g:?}");
}

#[test]
fn leader_rule_and_guidance() {
    // Focal agent with three visible neighbours ahead (0°, ±30°); they see nobody ahead.
    let c = 3f64.sqrt();
    let rows = [
        agent(0, 0.0, 0.0, 1.0, 0.0),
        agent(1, 2.0, 0.0, 1.0, 0.0),
        agent(2, c, 1.0, 1.0, 0.0),
        agent(3, c, -1.0, 1.0, 0.0),
    ];
    let dev = device();
    let snap = HerdState::from_rows(&rows, &dev).snapshot().unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let guided = World {
        obstacles: None,
        guidance: Guidance::Uniform([0.0, 2.0]),
        fixed_speed: None,
    };
    let m = model(Params::default(), guided.clone());
    let d = m.decide(&snap, &mut rng);
    assert_eq!(d.perception.front_count, vec![3, 0, 0, 0]);
    assert_eq!(d.leader, vec![false, true, true, true]);
    assert_eq!(d.guide[1], [0.0, 1.0]);
    // Raising the threshold to 3 makes the focal agent a leader too.
    let mut p = Params::default();
    p.constants.leader_max_neighbours = 3;
    let d3 = model(p, guided).decide(&snap, &mut rng);
    assert_eq!(d3.leader, vec![true; 4]);
    // Without guidance, leaders act as followers.
    let d0 = model(Params::default(), World::open()).decide(&snap, &mut rng);
    assert_eq!(d0.leader, vec![false; 4]);
    // A leader's next heading is the guidance direction, exactly.
    let f = ForceTensors::new(&theta_tensor(&m.params.to_vec(), &dev), &m.params.constants);
    let next = m.step(&f, &HerdState::from_rows(&rows, &dev), &d).unwrap();
    let s = next.snapshot().unwrap();
    assert_eq!(s.head[2], [0.0, 1.0]);
    assert!(
        s.head[0][1].abs() < 0.5,
        "the follower keeps heading roughly +x"
    );
}

#[test]
fn speed_follows_the_ou_process() {
    let mut p = Params::default();
    p.speed.mean = 2.0;
    p.speed.std = 0.0;
    let m = model(p, World::open());
    let dev = device();
    let rows = [agent(0, 0.0, 0.0, 1.0, 0.0), agent(1, 0.0, 1.0, 0.5, 0.0)];
    let s = HerdState::from_rows(&rows, &dev);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let d = m.decide(&s.snapshot().unwrap(), &mut rng);
    // v' = v − θ(v − v_μ)Δt with θ = 1, Δt = 0.04 (eq. 6 with v_σ = 0).
    let v = m.next_speeds(&[1.0, 0.5], &d);
    assert!(
        close(v[0], 1.0 + 0.04) && close(v[1], 0.5 + 1.5 * 0.04),
        "{v:?}"
    );
    // The position moves by Δt v' along the new heading.
    let f = ForceTensors::new(&theta_tensor(&m.params.to_vec(), &dev), &m.params.constants);
    let next = m.step(&f, &s, &d).unwrap().snapshot().unwrap();
    let moved = (next.pos[0][0].powi(2) + next.pos[0][1].powi(2)).sqrt();
    assert!(close(moved, 0.04 * 1.04), "{moved}");
}

fn random_rows(n: usize, seed: u64) -> Vec<AgentRow> {
    herdfit::herd::sim::random_herd(
        &herdfit::herd::sim::HerdSpec::standard(n),
        &Params::default().speed,
        &World::open(),
        seed,
    )
    .unwrap()
}

#[test]
fn replay_reproduces_a_live_run_exactly() {
    let dev = device();
    let m = model(
        Params::default(),
        World {
            obstacles: None,
            guidance: Guidance::Uniform([1.0, 0.3]),
            fixed_speed: None,
        },
    );
    let rows = random_rows(120, 4);
    let theta = theta_tensor(&m.params.to_vec(), &dev);
    let mut rec = Recording::new(rows.len());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let live = m
        .rollout(
            &theta,
            HerdState::from_rows(&rows, &dev),
            12,
            Decide::Live {
                rng: &mut rng,
                record: Some(&mut rec),
            },
            |_, _, _| Ok(()),
        )
        .unwrap()
        .snapshot()
        .unwrap();
    assert_eq!(rec.steps.len(), 12);
    assert!(rec.steps.iter().any(|s| s.leader.iter().any(|&l| l)));
    // Through a file and back.
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("rec.json");
    rec.save(&path).unwrap();
    let rec2 = Recording::load(&path).unwrap();
    assert_eq!(rec2, rec);
    let replayed = m
        .rollout::<rand_chacha::ChaCha8Rng>(
            &theta,
            HerdState::from_rows(&rows, &dev),
            12,
            Decide::Replay(&rec2),
            |_, _, _| Ok(()),
        )
        .unwrap()
        .snapshot()
        .unwrap();
    assert_eq!(live, replayed);
    // A recording that is too short is refused.
    let err = m
        .rollout::<rand_chacha::ChaCha8Rng>(
            &theta,
            HerdState::from_rows(&rows, &dev),
            13,
            Decide::Replay(&rec2),
            |_, _, _| Ok(()),
        )
        .unwrap_err();
    assert!(err.to_string().contains("12 steps"), "{err}");
}

#[test]
fn gradcheck_in_process_matches_finite_differences() {
    use herdfit::herd::gradcheck::{default_scenario, gradcheck, record};
    let sc = default_scenario(Params::default(), 60, 1).unwrap();
    let rec = record(&sc, 6, 1, &device()).unwrap();
    let r = gradcheck(&sc, 6, (Compute::Cpu, Precision::F64), 1e-4, &rec, || {}).unwrap();
    assert_eq!(r.parameters.len(), 12);
    assert!(r.max_rel_err < 1e-6, "{r:?}");
    // Every parameter, obstacles included, actually moves the objective.
    assert!(
        r.parameters.iter().all(|p| p.autodiff.abs() > 1e-7),
        "{r:?}"
    );
}
