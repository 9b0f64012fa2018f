//! Eq. 3: locally weighted linear regression within the chosen cluster (§5.2), allocation-free
//! with reusable buffers.

use super::features::V2;

/// Buffers of [`lwr`]'s normal equations.
#[derive(Default)]
pub struct LwrScratch {
    ata: Vec<f64>,
    atb: Vec<f64>,
    x: Vec<f64>,
    w: Vec<f64>,
}

/// Eq. 3, locally weighted linear regression at query `s`: β = (SᵀWS)⁻¹SᵀW a over the rows
/// (state s_i, action a_i, ‖s − s_i‖²), S's rows `[1, s_i − s]`, W_ii = exp(−½ ‖s − s_i‖²/h²);
/// the prediction at `s` is β's intercept. With too few rows or a singular system it falls back
/// to the weighted mean (the intercept-only fit). `h2 = ∞` and `ridge = 0` give ordinary least
/// squares; `ridge > 0` adds `ridge × (mean slope diagonal)` to the slopes' diagonal.
pub fn lwr(
    s: &[f64],
    rows: &[(&[f64], V2, f64)],
    h2: f64,
    ridge: f64,
    ata: &mut Vec<f64>,
    atb: &mut Vec<f64>,
) -> V2 {
    let mut sc = LwrScratch {
        ata: std::mem::take(ata),
        atb: std::mem::take(atb),
        ..LwrScratch::default()
    };
    let out = lwr_by(s, rows.len(), |r| rows[r], h2, ridge, &mut sc);
    *ata = sc.ata;
    *atb = sc.atb;
    out
}

/// [`lwr`] over `n` rows given by `row(r)`, with reusable buffers.
#[inline(always)]
pub fn lwr_by<'a>(
    s: &[f64],
    n: usize,
    row: impl Fn(usize) -> (&'a [f64], V2, f64),
    h2: f64,
    ridge: f64,
    sc: &mut LwrScratch,
) -> V2 {
    let d = s.len();
    let m = d + 1;
    let weight = |dist2: f64| {
        if h2.is_infinite() {
            1.0
        } else {
            (-0.5 * dist2 / h2).exp()
        }
    };
    // The design matrix [1, s_i − s] column by column, the weights and the actions.
    // Every entry of these buffers is written before it is read: grown, never cleared.
    grow(&mut sc.x, m * n);
    grow(&mut sc.w, 4 * n);
    let (x, w) = (&mut sc.x[..m * n], &mut sc.w[..4 * n]);
    let (w, rest) = w.split_at_mut(n);
    let (y0, rest) = rest.split_at_mut(n);
    let (y1, wx) = rest.split_at_mut(n);
    let (mut sw, mut mean) = (0.0, [0.0, 0.0]);
    for r in 0..n {
        let (si, a, dist2) = row(r);
        let wr = weight(dist2);
        w[r] = wr;
        sw += wr;
        mean[0] += wr * a[0];
        mean[1] += wr * a[1];
        (y0[r], y1[r]) = (a[0], a[1]);
        x[r] = 1.0;
        for (k, (a, b)) in si.iter().zip(s).enumerate() {
            x[(k + 1) * n + r] = a - b;
        }
    }
    if sw <= 1e-300 {
        // Every weight underflowed: the nearest row's action.
        return (0..n)
            .map(&row)
            .min_by(|x, y| x.2.total_cmp(&y.2))
            .map_or([0.0, 0.0], |r| r.1);
    }
    let mean = [mean[0] / sw, mean[1] / sw];
    if n < m {
        return mean;
    }
    // SᵀWS (upper triangle, then mirrored) and SᵀWa as dot products of columns.
    grow(&mut sc.ata, m * m);
    grow(&mut sc.atb, 2 * m);
    let (ata, atb) = (&mut sc.ata[..m * m], &mut sc.atb[..2 * m]);
    for i in 0..m {
        let xi = &x[i * n..(i + 1) * n];
        for ((v, a), b) in wx.iter_mut().zip(w.iter()).zip(xi) {
            *v = a * b;
        }
        for j in i..m {
            ata[i * m + j] = dot(wx, &x[j * n..(j + 1) * n]);
        }
        atb[i] = dot(wx, y0);
        atb[m + i] = dot(wx, y1);
    }
    for i in 0..m {
        for j in 0..i {
            ata[i * m + j] = ata[j * m + i];
        }
    }
    if ridge > 0.0 {
        let lam = ridge * (1..m).map(|i| ata[i * m + i]).sum::<f64>() / d.max(1) as f64;
        for i in 1..m {
            ata[i * m + i] += lam;
        }
    }
    if cholesky_solve(ata, atb, m) {
        [sc.atb[0], sc.atb[m]]
    } else {
        mean
    }
}

/// Makes `v` at least `len` long (new entries 0; old ones kept, to be overwritten).
#[inline(always)]
fn grow(v: &mut Vec<f64>, len: usize) {
    if v.len() < len {
        v.resize(len, 0.0);
    }
}

/// Σ a_i b_i in four interleaved partial sums (vectorised; a fixed order, so deterministic).
#[inline(always)]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (u, v) in ca.zip(cb) {
        for ((c, x), y) in acc.iter_mut().zip(u).zip(v) {
            *c += x * y;
        }
    }
    let mut s = (acc[0] + acc[1]) + (acc[2] + acc[3]);
    for (u, v) in ra.iter().zip(rb) {
        s += u * v;
    }
    s
}

/// Solves `A [x y] = [b0 b1]` for symmetric positive definite `A` (`m × m`) in place (the
/// solutions replace `b`); `false` when A is not (numerically) positive definite.
#[inline(always)]
fn cholesky_solve(a: &mut [f64], b: &mut [f64], m: usize) -> bool {
    let scale = (0..m).map(|i| a[i * m + i].abs()).fold(0.0, f64::max);
    for j in 0..m {
        let mut diag = a[j * m + j];
        for k in 0..j {
            diag -= a[j * m + k] * a[j * m + k];
        }
        if diag <= 1e-12 * scale.max(1e-300) {
            return false;
        }
        let l = diag.sqrt();
        a[j * m + j] = l;
        for i in j + 1..m {
            let mut v = a[i * m + j];
            for k in 0..j {
                v -= a[i * m + k] * a[j * m + k];
            }
            a[i * m + j] = v / l;
        }
    }
    for c in 0..2 {
        let b = &mut b[c * m..(c + 1) * m];
        for i in 0..m {
            let mut v = b[i];
            for k in 0..i {
                v -= a[i * m + k] * b[k];
            }
            b[i] = v / a[i * m + i];
        }
        for i in (0..m).rev() {
            let mut v = b[i];
            for k in i + 1..m {
                v -= a[k * m + i] * b[k];
            }
            b[i] = v / a[i * m + i];
        }
    }
    true
}
