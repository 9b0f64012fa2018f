//! Induced-power savings of a V formation against wing-tip spacing (WTS), from Hummel's g_ij
//! (Klotsman & Tal eq. 1, C = 1): the numbers behind RESULTS.md's energy comparison.
//!
//! `cargo run --release --example flock_energy`
//!
//! A V of N birds with 30° sides and neighbours `1 + WTS` wingspans apart laterally (WTS: the gap
//! between adjacent wing tips, negative when they overlap). By Munk's theorem the flock's mean
//! saving depends on the lateral spacing only, not on the V's depth.

use herdfit::flock::power;

fn v(n: usize, wts: f64) -> Vec<[f64; 2]> {
    let gap = 1.0 + wts;
    let tan = 30f64.to_radians().tan();
    let mut p = vec![[0.0, 0.0]];
    for k in 1..n {
        let side = if k % 2 == 1 { -1.0 } else { 1.0 };
        let u = k.div_ceil(2) as f64 * gap;
        p.push([side * u, -u / tan]);
    }
    p
}

fn mean(e: &[f64]) -> f64 {
    e.iter().sum::<f64>() / e.len() as f64
}

/// WTS at which the V's mean saving equals `want` (bisection on the monotone branch WTS > −(1 − π/4)).
fn wts_for(n: usize, want: f64) -> f64 {
    let (mut a, mut b) = (power::VORTEX_SPAN - 1.0 + 1e-6, 5.0);
    for _ in 0..100 {
        let m = 0.5 * (a + b);
        if mean(&power::savings(&v(n, m)).unwrap()) > want {
            a = m;
        } else {
            b = m;
        }
    }
    0.5 * (a + b)
}

fn main() {
    println!("induced-power saving (%) of a 30° V, Hummel 1983 horseshoe model (C = 1)");
    println!(
        "{:>4} {:>7} {:>8} {:>8} {:>8} {:>8} {:>8}",
        "N", "WTS/b", "mean", "leader", "2nd", "middle", "tip"
    );
    for n in [9usize, 15, 25, 41] {
        for wts in [-0.15, -0.1, -0.05, 0.0, 0.1, 0.2, 0.5, 1.0] {
            let e = power::savings(&v(n, wts)).unwrap();
            let mid = e[(n - 1) / 2 - ((n - 1) / 2) % 2 + 1];
            println!(
                "{n:>4} {wts:>7.2} {:>8.1} {:>8.1} {:>8.1} {:>8.1} {:>8.1}",
                100.0 * mean(&e),
                100.0 * e[0],
                100.0 * e[1],
                100.0 * mid,
                100.0 * e[n - 1]
            );
        }
    }
    println!();
    println!("WTS/b at which the V's mean saving equals the field estimates");
    for n in [9usize, 15, 25, 41] {
        println!(
            "N = {n:>2}: 14 % (pink-footed geese, Cutts & Speakman 1994) at WTS = {:+.3} b; 36 % (Canada geese, Hainsworth 1987) at WTS = {:+.3} b",
            wts_for(n, 0.14),
            wts_for(n, 0.36)
        );
    }
    let pair = power::g(1.0, 1e9);
    println!();
    println!(
        "one bird far behind one other at WTS = 0: {:.1} %; abreast: {:.1} %",
        100.0 * pair,
        100.0 * power::g(1.0, 0.0)
    );
}
