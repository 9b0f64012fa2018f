//! Where a track rollout's error comes from (issue #49): the leader rule (§5.1), eq. 6's speeds
//! and the forces, on the conditioned windows of a clip's tracks.
//!
//! For the frames `a..b` of a clip made by `import-tracks` (windows every 0.5 s, eq. 6 learnt
//! from frames `0..a`), it rolls out every animal of every window for `horizon` seconds among
//! its replayed neighbours with the generic set (every parameter 0.5) and with the force weights
//! at 0, each with the leader rule on (the clip's guidance) and off, and each with eq. 6's noisy,
//! expected and tracked speeds, and prints the ADE (BL) beside constant velocity and the share
//! of the rolled-out animal-steps that led. The first window of each case with an ADE above
//! 0.3 BL is printed step by step (tracked against rolled-out position, heading, speed, leader).
//!
//! ```text
//! herdfit import-tracks students003.txt --fps 2.5 --body-length-m 0.3 --out students
//! cargo run --release --example track_leaders -- students 135 270 1
//! ```
use herdfit::backend::{cpu_device, Precision};
use herdfit::herd::params::{Params, N_PARAMS};
use herdfit::herd::sim::{theta_tensor, Decide, ForceTensors};
use herdfit::herd::track_fit::{
    learn_speed, load_input, roll, Leaders, Rollout, Speeds, TrackClip, Window,
};
use herdfit_kernels::P2;
use rand::SeedableRng;

/// One window's rolled-out animals: per step, positions, headings, speeds, leaders.
#[derive(Default)]
struct Path {
    pos: Vec<Vec<P2>>,
    head: Vec<Vec<P2>>,
    speed: Vec<Vec<f64>>,
    lead: Vec<Vec<bool>>,
}

fn trace(clip: &TrackClip, w: &Window, id: u64, i: usize, p: &Path) {
    let v0 = clip.tracks.back_vel(w.start, id).unwrap();
    println!(
        "    window f0={} animal {id}: start velocity ({:.2}, {:.2}), guidance there {:?}",
        w.start,
        v0[0],
        v0[1],
        {
            let mut m = clip.model.clone();
            m.world.guidance = clip.guidance_for(w.start);
            m.world.guidance_at(clip.tracks.pos(w.start, id).unwrap())
        }
    );
    for k in 1..=w.steps.min(6) {
        let t = clip.tracks.pos(w.start + k, id).unwrap();
        let v = clip.tracks.back_vel(w.start + k, id).unwrap();
        let (q, h) = (p.pos[k - 1][i], p.head[k - 1][i]);
        println!(
            "      step {k}: tracked ({:.3}, {:.3}) v ({:.2}, {:.2}) | rolled out ({:.3}, {:.3}) \
             heading ({:.2}, {:.2}) speed {:.2} leader {}",
            t[0],
            t[1],
            v[0],
            v[1],
            q[0],
            q[1],
            h[0],
            h[1],
            p.speed[k - 1][i],
            p.lead[k - 1][i]
        );
    }
}

/// ADE, constant velocity's ADE, samples, leader share of one case over the windows.
fn case(clip: &TrackClip, p: &Params, speeds: Speeds, steps: usize, show: bool) -> [f64; 4] {
    let device = cpu_device(Precision::F64).unwrap();
    let forces = ForceTensors::new(&theta_tensor(&p.to_vec(), &device), &p.constants);
    let mut clip = clip.clone();
    clip.model.params = p.clone();
    let fps = clip.tracks.fps;
    let stride = ((0.5 * fps).round() as usize).max(1);
    let (mut ade, mut cv, mut n, mut led, mut seen) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let mut shown = !show;
    let mut f0 = clip.frames.start + 1;
    while f0 + steps < clip.frames.end {
        let w = Window {
            clip: 0,
            start: f0,
            steps,
        };
        let rows = clip.starters(f0);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(f0 as u64);
        let mut p = Path::default();
        let decide = Decide::Live {
            rng: &mut rng,
            record: None,
        };
        let ids = roll(
            &clip,
            &w,
            Rollout::Conditioned,
            speeds,
            &forces,
            &device,
            decide,
            |_, s, l| {
                let snap = s.snapshot()?;
                p.pos.push(snap.pos);
                p.head.push(snap.head);
                p.speed.push(snap.speed);
                p.lead.push(l.to_vec());
                Ok(())
            },
        )
        .unwrap();
        f0 += stride;
        let Some(ids) = ids else { continue };
        for (i, &id) in ids.iter().enumerate() {
            let Some(track) = (1..=steps)
                .map(|k| clip.tracks.pos(w.start + k, id))
                .collect::<Option<Vec<P2>>>()
            else {
                continue;
            };
            let r = &rows[i];
            let (mut e, mut c) = (0.0, 0.0);
            for (k, t) in track.iter().enumerate() {
                let q = p.pos[k][i];
                let s = (k + 1) as f64 / fps;
                e += (q[0] - t[0]).hypot(q[1] - t[1]);
                c += (r.x + r.vx * s - t[0]).hypot(r.y + r.vy * s - t[1]);
                led += p.lead[k][i] as u8 as f64;
                seen += 1.0;
            }
            ade += e / steps as f64;
            cv += c / steps as f64;
            n += 1.0;
            if !shown && e / steps as f64 > 0.3 {
                shown = true;
                trace(&clip, &w, id, i, &p);
            }
        }
    }
    [ade / n, cv / n, n, led / seen]
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    if a.len() != 5 {
        eprintln!("usage: track_leaders CLIP/ A B HORIZON_S (scored frames A..B, eq. 6 from 0..A)");
        std::process::exit(2);
    }
    let dir = std::path::Path::new(&a[1]);
    let (from, to): (usize, usize) = (a[2].parse().unwrap(), a[3].parse().unwrap());
    let horizon: f64 = a[4].parse().unwrap();
    let base = Params::default();
    let with = |leaders| load_input(dir, None, from..to, (leaders, 0.0), &base).unwrap();
    let clips = [(true, with(Leaders::Field)), (false, with(Leaders::Off))];
    let radius = base.constants.perception_radius;
    let (speed, fit) = learn_speed(&[(&clips[0].1.tracks, 0..from)], radius, &base.speed).unwrap();
    println!(
        "{}: frames {from}..{to} at {} fps; eq. 6 from 0..{from}: v_μ {:.3} BL/s, θ_OU {:.3} /s, \
         v_σ {:.3} ({} samples)",
        a[1], clips[0].1.tracks.fps, speed.mean, speed.reversion, speed.std, fit.samples
    );
    let steps = ((horizon * clips[0].1.tracks.fps).round() as usize).max(1);
    let mut generic = base.with_vec(&[0.5; N_PARAMS]);
    generic.speed = speed;
    let mut v = [0.5; N_PARAMS];
    [0, 3, 6, 9].iter().for_each(|&i| v[i] = 0.0);
    let zero = generic.with_vec(&v);
    println!("| set | leaders | speeds | ADE (BL) | constant velocity | animals | leader share |");
    println!("|---|---|---|---:|---:|---:|---:|");
    for (name, p) in [("generic", &generic), ("force weights 0", &zero)] {
        for (leaders, clip) in &clips {
            for speeds in [Speeds::Noisy, Speeds::Expected, Speeds::Tracks] {
                let r = case(clip, p, speeds, steps, name == "generic");
                println!(
                    "| {name} | {} | {speeds} | {:.4} | {:.4} | {} | {:.3} |",
                    if *leaders { "field" } else { "off" },
                    r[0],
                    r[1],
                    r[2],
                    r[3]
                );
            }
        }
    }
}
