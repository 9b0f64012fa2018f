//! Is the fitted set better than the baseline, or is the difference the simulation's noise?
//!
//! Every set of a validation is simulated with the same seeds `0..K`, and a seed fixes the
//! herd drawn from the first held-out frame's fields and the speed noise ξ (eq. 6): seed `s`
//! of the fitted set and seed `s` of the baseline are a pair with common random numbers. The
//! per-seed differences of the mean held-out errors are independent across seeds, so their mean
//! and its standard error `sd/√K` say how far the difference of the report's errors can be
//! trusted; the verdict uses the two-sided 95 % Student-t interval with K − 1 degrees of freedom.

use super::{SetReport, MEASURES};
use serde::Serialize;

/// The four emergent measures whose errors are summed ("Σ 4" of RESULTS.md §6).
const EMERGENT: std::ops::Range<usize> = 2..6;

/// The name of the row holding the sum of the four emergent-measure errors.
pub const SUM_OF_FOUR: &str = "sum_of_four_measures";

/// One measure of one paired comparison.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairedRow {
    pub measure: String,
    /// Mean over seeds of (set's error − the other set's error): negative = the set is better.
    pub difference: f64,
    /// Standard error of `difference` (sample std of the per-seed differences / √K); absent
    /// with one seed.
    pub standard_error: Option<f64>,
    /// "better", "worse", "within noise" (the 95 % t-interval holds 0), "same" (every per-seed
    /// difference is 0) or "one seed" (no noise estimate).
    pub verdict: String,
}

/// The first set of a report against another, seed by seed.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Paired {
    pub set: String,
    pub against: String,
    pub seeds: usize,
    pub rows: Vec<PairedRow>,
}

/// The two-sided 95 % quantile of Student's t with `dof` degrees of freedom (tabulated; the
/// normal 1.96 beyond 120).
pub fn t975(dof: usize) -> f64 {
    const T: [f64; 30] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228, 2.201, 2.179, 2.160,
        2.145, 2.131, 2.120, 2.110, 2.101, 2.093, 2.086, 2.080, 2.074, 2.069, 2.064, 2.060, 2.056,
        2.052, 2.048, 2.045, 2.042,
    ];
    match dof {
        0 => f64::INFINITY,
        1..=30 => T[dof - 1],
        31..=40 => 2.021,
        41..=60 => 2.000,
        61..=120 => 1.980,
        _ => 1.960,
    }
}

/// Mean, standard error and verdict of per-seed differences.
pub fn paired_row(measure: &str, diffs: &[f64]) -> PairedRow {
    let k = diffs.len();
    let mean = diffs.iter().sum::<f64>() / k.max(1) as f64;
    let (standard_error, verdict) = if diffs.iter().all(|&d| d == 0.0) {
        (Some(0.0).filter(|_| k > 1), "same")
    } else if k < 2 {
        (None, "one seed")
    } else {
        let var = diffs.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / (k - 1) as f64;
        let se = (var / k as f64).sqrt();
        let half = t975(k - 1) * se;
        let v = if mean + half < 0.0 {
            "better"
        } else if mean - half > 0.0 {
            "worse"
        } else {
            "within noise"
        };
        (Some(se), v)
    };
    PairedRow {
        measure: measure.to_string(),
        difference: mean,
        standard_error,
        verdict: verdict.to_string(),
    }
}

/// `a` against `b` over their common seeds: the six measures of [`MEASURES`] and the sum of the
/// four emergent-measure errors. `None` when either set has no per-seed errors (a validation of
/// the seeds' mean prediction).
pub fn compare(a: &SetReport, b: &SetReport) -> Option<Paired> {
    let k = a.seed_errors.len().min(b.seed_errors.len());
    if k == 0 {
        return None;
    }
    let pairs = || a.seed_errors.iter().zip(&b.seed_errors);
    let mut rows: Vec<PairedRow> = MEASURES
        .iter()
        .enumerate()
        .map(|(m, name)| {
            let d: Vec<f64> = pairs().map(|(x, y)| x[m] - y[m]).collect();
            paired_row(name, &d)
        })
        .collect();
    let sum = |e: &[f64; 6]| e[EMERGENT].iter().sum::<f64>();
    let d: Vec<f64> = pairs().map(|(x, y)| sum(x) - sum(y)).collect();
    rows.push(paired_row(SUM_OF_FOUR, &d));
    Some(Paired {
        set: a.name.clone(),
        against: b.name.clone(),
        seeds: k,
        rows,
    })
}

/// The first set against every other one.
pub fn comparisons(sets: &[SetReport]) -> Vec<Paired> {
    let Some((first, rest)) = sets.split_first() else {
        return Vec::new();
    };
    rest.iter().filter_map(|b| compare(first, b)).collect()
}

/// The comparisons as Markdown sections (empty when there are none).
pub fn markdown(paired: &[Paired]) -> String {
    let mut s = String::new();
    for p in paired {
        s.push_str(&format!(
            "## {} against {}, seed by seed\n\nDifference of the mean held-out error ({} − {}; negative: {} is better) over {} seed(s) with common random numbers (the same starting herd and speed noise per seed), its standard error, and whether the 95 % t-interval excludes 0.\n\n| measure | difference | standard error | verdict |\n|---|---:|---:|---|\n",
            p.set, p.against, p.set, p.against, p.set, p.seeds
        ));
        for r in &p.rows {
            let se = r.standard_error.map_or("—".into(), |x| format!("{x:.4}"));
            s.push_str(&format!(
                "| {} | {:+.4} | {se} | {} |\n",
                r.measure, r.difference, r.verdict
            ));
        }
        s.push('\n');
    }
    s
}

/// Per seed, the mean over the held-out frames of each measure's error (finite values only),
/// from errors pushed seed by seed, `frames` per seed.
pub fn seed_means(errs: &[Vec<f64>], seeds: usize, frames: usize) -> Vec<[f64; 6]> {
    (0..seeds)
        .map(|s| {
            let mut out = [f64::NAN; 6];
            for (m, e) in errs.iter().enumerate().take(6) {
                let chunk = e.get(s * frames..(s + 1) * frames).unwrap_or(&[]);
                let v: Vec<f64> = chunk.iter().copied().filter(|x| x.is_finite()).collect();
                if !v.is_empty() {
                    out[m] = v.iter().sum::<f64>() / v.len() as f64;
                }
            }
            out
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn verdicts_follow_the_t_interval() {
        // mean −1, sample sd √(2/3), K = 4: se 0.408, half-width 3.182 · 0.408 = 1.30 → within
        // noise.
        let r = paired_row("x", &[-2.0, -1.0, 0.0, -1.0]);
        assert!((r.difference + 1.0).abs() < 1e-12);
        assert_eq!(r.verdict, "within noise");
        let sd = (2.0f64 / 3.0).sqrt();
        assert!((r.standard_error.unwrap() - sd / 2.0).abs() < 1e-12);
        // A steady improvement of 1 ± 0.1 over 5 seeds is better; its mirror is worse.
        let d = [-1.1, -0.9, -1.0, -1.05, -0.95];
        assert_eq!(paired_row("x", &d).verdict, "better");
        let w: Vec<f64> = d.iter().map(|x| -x).collect();
        assert_eq!(paired_row("x", &w).verdict, "worse");
        assert_eq!(paired_row("x", &[0.0, 0.0, 0.0]).verdict, "same");
        assert_eq!(paired_row("x", &[0.0, 0.0, 0.0]).standard_error, Some(0.0));
        let one = paired_row("x", &[-3.0]);
        assert_eq!(
            (one.verdict.as_str(), one.standard_error),
            ("one seed", None)
        );
        assert_eq!(t975(1), 12.706);
        assert_eq!(t975(1000), 1.96);
    }

    #[test]
    fn seed_means_split_the_errors_by_seed_and_skip_non_finite_values() {
        let errs: Vec<Vec<f64>> = (0..6)
            .map(|m| vec![1.0, 3.0, f64::NAN, 10.0 + m as f64, 20.0, 30.0])
            .collect();
        let s = seed_means(&errs, 2, 3);
        assert_eq!(s.len(), 2);
        assert_eq!(s[0][0], 2.0);
        assert_eq!(s[1][5], (15.0 + 20.0 + 30.0) / 3.0);
    }
}
