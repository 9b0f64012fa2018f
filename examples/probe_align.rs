use herdfit::backend::Precision;
use herdfit::data::ClipFields;
use herdfit::herd::fit::still::{stationary_clip, still_measures, StillConfig};
use herdfit::herd::params::{Params, N_PARAMS};
use rand::{Rng, SeedableRng};
fn main() -> herdfit::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let still = ClipFields::load(std::path::Path::new(&args[1]))?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args[2].parse().unwrap());
    for k in 0..40 {
        let mut v = [0.0; N_PARAMS];
        v.iter_mut().for_each(|x| *x = rng.gen_range(0.0..1.0));
        Params::clamp_vec(&mut v);
        let p = Params::neutral().with_vec(&v);
        let mut out = format!("{k}");
        for cfg in [
            StillConfig::default(),
            StillConfig {
                settle: 500,
                average: 250,
            },
        ] {
            let clip = stationary_clip(&still, &cfg, &p.speed);
            let [_, m] = still_measures(&clip, &p, &cfg, 0, 1, Precision::F32)?;
            out += &format!(" pol {:.3} crowd {:.3}", m.polarization, m.crowding);
        }
        println!(
            "{out}  theta {:?}",
            v.iter()
                .map(|x| (x * 100.0).round() / 100.0)
                .collect::<Vec<_>>()
        );
    }
    Ok(())
}
