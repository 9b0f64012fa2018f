use herdfit::data::camera::Camera;
use herdfit::data::jackdaw::load_tracks;
use herdfit::lift::frame::frame_by_frame;
use herdfit::lift::sequence::{energy_terms, whole_sequence};
use herdfit::lift::{project_tracks, LiftConfig, Observations};
use herdfit::progress::NoProgress;
use std::path::Path;

fn rel(d: &[f64], t: &[f64]) -> f64 {
    let n = d.len() as f64;
    let m = t.iter().sum::<f64>() / n;
    (d.iter().zip(t).map(|(a, b)| (a - b).powi(2)).sum::<f64>() / n).sqrt() / m
}

fn diag(d: &[f64], t: &[f64]) -> String {
    let k = d.iter().zip(t).map(|(a, b)| a * b).sum::<f64>() / d.iter().map(|a| a * a).sum::<f64>();
    let ds: Vec<f64> = d.iter().map(|a| a * k).collect();
    let md = d.iter().sum::<f64>() / t.iter().sum::<f64>();
    format!(
        "rel {:.3} ratio {:.3} scaled {:.3}",
        rel(d, t),
        md,
        rel(&ds, t)
    )
}

fn main() {
    let a: Vec<String> = std::env::args().collect();
    let truth = load_tracks(Path::new(&a[1])).unwrap();
    let cam = Camera::load(Path::new(&a[2])).unwrap();
    let crop = a[3] == "crop";
    let (t2, td) = project_tracks(&truth, &cam, crop).unwrap();
    let obs = Observations::new(&t2, &cam).unwrap();
    for c in &a[4..] {
        let cfg: LiftConfig = serde_json::from_str(c).unwrap();
        let (cfg, _) = herdfit::lift::estimate::resolve(&obs, &cfg).unwrap();
        let t0 = std::time::Instant::now();
        let fbf = frame_by_frame(&obs, &cfg, &mut NoProgress).unwrap();
        let (s, log) = whole_sequence(&obs, &fbf, &cfg, &mut NoProgress).unwrap();
        println!(
            "{c}: fbf {:.3} seq {} E {:.4} its {:?} {:.1}s",
            rel(&fbf, &td),
            diag(&s, &td),
            log.end.total,
            log.iterations,
            t0.elapsed().as_secs_f64()
        );
        if std::env::var("TERMS").is_ok() {
            println!("   truth {:?}", energy_terms(&obs, &td, &cfg).unwrap());
            println!("   found {:?}", log.end);
        }
        if std::env::var("INITS").is_ok() {
            for (name, init) in [
                (
                    "truth x1.3",
                    td.iter().map(|d| d * 1.3).collect::<Vec<f64>>(),
                ),
                ("truth x0.7", td.iter().map(|d| d * 0.7).collect()),
                ("const mid", vec![0.5 * (cfg.near() + cfg.far()); td.len()]),
            ] {
                let (s, log) = whole_sequence(&obs, &init, &cfg, &mut NoProgress).unwrap();
                println!(
                    "   from {name}: seq {} E {:.4}",
                    diag(&s, &td),
                    log.end.total
                );
            }
        }
    }
}
