use herdfit::backend::Precision;
use herdfit::data::ClipFields;
use herdfit::herd::fit::still::{stationary_clip, still_measures, StillConfig};
use herdfit::herd::params::Params;
fn main() -> herdfit::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let still = ClipFields::load(std::path::Path::new(&args[1]))?;
    for f in &args[2..] {
        let p = Params::load(std::path::Path::new(f))?;
        for cfg in [
            StillConfig::default(),
            StillConfig {
                settle: 500,
                average: 250,
            },
        ] {
            let clip = stationary_clip(&still, &cfg, &p.speed);
            let [_, m] = still_measures(&clip, &p, &cfg, 0, 2, Precision::F32)?;
            println!(
                "{f} {}: pol {:.3} crowd {:.3} smooth {:.3} derr {:.3}",
                cfg.settle, m.polarization, m.crowding, m.smooth_density_error, m.density_error
            );
        }
        let v = p.to_vec();
        println!(
            "   theta {:?}",
            v.iter()
                .map(|x| (x * 1000.0).round() / 1000.0)
                .collect::<Vec<_>>()
        );
    }
    Ok(())
}
