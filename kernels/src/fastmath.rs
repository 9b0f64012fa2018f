//! `libm`'s `exp` with the same bytes, inlined: the force kernel evaluates three per pair
//! (eq. 4), and inside the kernel loop the compiler can overlap them, which a call to the
//! out-of-line `libm::exp` (with its special-case branches) cannot.

// FreeBSD e_exp.c constants, as in libm 0.2, digit for digit as printed there (they round to the
// same f64 as clippy's shorter forms).
#![allow(clippy::excessive_precision)]
const LN2HI: f64 = 6.931_471_803_691_238_164_90e-1;
const LN2LO: f64 = 1.908_214_929_270_587_700_02e-10;
const INVLN2: f64 = std::f64::consts::LOG2_E; // 1.44269504088896338700 in e_exp.c: the same f64
const P1: f64 = 1.666_666_666_666_660_190_37e-1;
const P2: f64 = -2.777_777_777_701_559_338_42e-3;
const P3: f64 = 6.613_756_321_437_934_361_17e-5;
const P4: f64 = -1.653_390_220_546_525_153_90e-6;
const P5: f64 = 4.138_136_797_057_238_460_39e-8;

/// The high word of |x|, which libm's `exp` branches on.
#[inline(always)]
fn high(x: f64) -> u32 {
    ((x.to_bits() >> 32) as u32) & 0x7fff_ffff
}

/// Whether |x| (high word `h`) lies in 2⁻²⁸ < |x| < 512, where [`exp_reduced`] is libm's `exp`.
#[inline(always)]
fn in_range(h: u32) -> bool {
    (0x3e30_0001..0x4080_0000).contains(&h)
}

/// libm's argument reduction and rational approximation of `e^x` for x in [`in_range`] (high
/// word `h`), with k chosen by selects instead of branches: k = 0 for |x| ≤ ½ ln 2, where
/// `x − 0·ln2hi` and `0·ln2lo` are exact, so the one formula is libm's both ways; the final
/// `scalbn(y, k)` is one exact multiplication by 2^k (|k| ≤ 739 keeps y·2^k normal).
#[inline(always)]
fn exp_reduced(x: f64, h: u32) -> f64 {
    let half = if x < 0.0 { -0.5 } else { 0.5 };
    let one = if x < 0.0 { -1 } else { 1 };
    let far = (INVLN2 * x + half) as i32;
    let k = if h >= 0x3ff0_a2b2 {
        far
    } else if h > 0x3fd6_2e42 {
        one
    } else {
        0
    };
    let kf = k as f64;
    let hi = x - kf * LN2HI;
    let lo = kf * LN2LO;
    let r = hi - lo;
    let rr = r * r;
    let c = r - rr * (P1 + rr * (P2 + rr * (P3 + rr * (P4 + rr * P5))));
    let y = 1.0 + (r * c / (2.0 - c) - lo + hi);
    y * f64::from_bits(((0x3ff + k) as u64) << 52)
}

/// `e^x`, bit for bit `libm::exp(x)`: inline in 2⁻²⁸ < |x| < 512 (every weight of a herd at its
/// parameters' scale), `libm::exp` elsewhere.
#[inline(always)]
pub fn exp(x: f64) -> f64 {
    let h = high(x);
    if in_range(h) {
        exp_reduced(x, h)
    } else {
        libm::exp(x)
    }
}

/// Three `e^x` at once, bit for bit `[libm::exp(x[0]), libm::exp(x[1]), libm::exp(x[2])]`: the
/// force kernel's three neighbour weights (eq. 4). When all three are in range they run as
/// independent straight-line chains the CPU overlaps (two SIMD lanes where the compiler pairs
/// them; every lane rounds as the scalar operation does).
#[inline(always)]
pub fn exp3(x: [f64; 3]) -> [f64; 3] {
    let h = [high(x[0]), high(x[1]), high(x[2])];
    if !(in_range(h[0]) && in_range(h[1]) && in_range(h[2])) {
        return [exp(x[0]), exp(x[1]), exp(x[2])];
    }
    [
        exp_reduced(x[0], h[0]),
        exp_reduced(x[1], h[1]),
        exp_reduced(x[2], h[2]),
    ]
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};

    #[test]
    fn exp_has_libms_bytes() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
        let check = |x: f64| {
            assert_eq!(super::exp(x).to_bits(), libm::exp(x).to_bits(), "x = {x:e}");
        };
        for _ in 0..200_000 {
            check(rng.gen_range(-60.0..2.0));
            check(rng.gen_range(-800.0..800.0));
            check(rng.gen_range(-1e-6..1e-6));
        }
        // The edges of every branch, and the special values.
        for b in [
            0x3e30_0000u64,
            0x3e30_0001,
            0x3fd6_2e42,
            0x3fd6_2e43,
            0x3ff0_a2b1,
            0x3ff0_a2b2,
            0x407f_ffff,
            0x4080_0000,
            0x4086_232b,
        ] {
            for low in [0u64, 1, 0xffff_ffff] {
                let bits = b << 32 | low;
                check(f64::from_bits(bits));
                check(-f64::from_bits(bits));
            }
        }
        for x in [
            0.0,
            -0.0,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -745.2,
            709.8,
            1e-320,
        ] {
            check(x);
        }
        assert!(super::exp(f64::NAN).is_nan());
    }

    #[test]
    fn exp3_has_libms_bytes() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(18);
        let check = |x: [f64; 3]| {
            let got = super::exp3(x);
            for l in 0..3 {
                assert_eq!(got[l].to_bits(), libm::exp(x[l]).to_bits(), "x = {x:?}");
            }
        };
        for _ in 0..200_000 {
            // Every lane in range (the straight-line path), weights' typical arguments.
            check([0; 3].map(|_| rng.gen_range(-60.0..2.0)));
            check([0; 3].map(|_| rng.gen_range(-1.2..1.2)));
            check([0; 3].map(|_| rng.gen_range(-511.0..511.0)));
            // One lane out of range: every lane through `exp`.
            check([rng.gen_range(-3.0..0.0), rng.gen_range(-1e-9..1e-9), -600.0]);
        }
        // The branch edges of the reduction, in each lane.
        let edges: Vec<f64> = [
            0x3e30_0001u64,
            0x3fd6_2e42,
            0x3fd6_2e43,
            0x3ff0_a2b1,
            0x3ff0_a2b2,
            0x407f_ffff,
        ]
        .iter()
        .flat_map(|&b| [0u64, 1, 0xffff_ffff].map(move |low| f64::from_bits(b << 32 | low)))
        .flat_map(|v| [v, -v])
        .collect();
        for (i, &a) in edges.iter().enumerate() {
            let b = edges[(i + 7) % edges.len()];
            let c = edges[(i + 13) % edges.len()];
            check([a, b, c]);
        }
        check([0.0, -1.0, 1.0]);
        check([f64::NAN, -1.0, 1.0]);
    }
}
