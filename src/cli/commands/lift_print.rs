//! What `herdfit lift run` and `lift evaluate` print: the evaluation table, the v_target and
//! bounds a lift used and where they came from, and the lift's self-assessment.

use std::path::Path;

pub(super) fn print_eval(r: &crate::lift::eval::EvalReport, out: &Path, secs: f64) {
    let u = r.camera.units.as_str();
    println!(
        "lift evaluate: {} birds, {} frames, {} points; mean true depth {:.2} {u}; flock extent {:.2} {u} (depth {:.2} {u}); truth's closest pair {}",
        r.birds,
        r.frames,
        r.observations,
        r.truth.mean_depth,
        r.truth.extent,
        r.truth.depth_extent,
        r.truth.min_distance.map_or("–".into(), |d| format!("{d:.3} {u}"))
    );
    println!(
        "  {:<16} {:>10} {:>10} {:>10} {:>9} {:>12} {:>9} {:>22}",
        "estimate",
        "depth RMSE",
        "(relative)",
        "3D RMSE",
        "/ extent",
        "closest pair",
        "< d_sep/2",
        "speed change vs truth"
    );
    for m in &r.methods {
        println!(
            "  {:<16} {:>10.3} {:>9.1}% {:>10.3} {:>9.2} {:>12} {:>9} {:>6.2} {:>6.2} {:>6.2}",
            m.name,
            m.depth_rmse,
            100.0 * m.depth_rmse_relative,
            m.position_rmse,
            m.position_rmse_per_extent,
            m.checks
                .min_distance
                .map_or("–".into(), |d| format!("{d:.3}")),
            m.checks.pairs_below_half_d_sep,
            m.speed_change_ratio[0],
            m.speed_change_ratio[1],
            m.speed_change_ratio[2]
        );
    }
    println!(
        "  (speed change: mean, median, p90 over the truth's); {secs:.1} s; wrote {}",
        out.display()
    );
    print_estimate(&r.estimate, u);
    println!(
        "  the truth's median speed {:.4} {u}/frame: v_target is {:+.1} % off",
        r.truth.median_speed,
        100.0 * (r.estimate.v_target / r.truth.median_speed - 1.0)
    );
    print_confidence(&r.confidence);
}

/// v_target and the bounds, and where they came from.
pub(super) fn print_estimate(e: &crate::lift::estimate::Estimate, u: &str) {
    use crate::lift::estimate::Source;
    let how = |s: Source| match s {
        Source::Given => "given",
        Source::Estimated => "estimated",
    };
    println!(
        "  v_target {:.4} {u}/frame ({}; the tracks turn at {:.3} rad/s{}, which the speed prior \
         reads as {:.1} m/s{}); bounds {:.1}–{:.1} {u} ({})",
        e.v_target,
        how(e.v_target_source),
        e.turn_rate,
        e.foreshortening.map_or(String::new(), |f| format!(
            ", {f:.2}× their rate on a horizontal plane"
        )),
        e.speed_mps,
        if e.extrapolated { ", extrapolated" } else { "" },
        e.d_near,
        e.d_far,
        how(e.bounds_source)
    );
}

/// The self-assessment, with a line per reason not to trust the lift.
pub(super) fn print_confidence(c: &crate::lift::confidence::Confidence) {
    let restart = c.disagreement.map_or("no restart".into(), |d| {
        format!("a restart ends {:.1} % away", 100.0 * d)
    });
    println!(
        "  confidence: {restart}; per-bird depth structure {:.1} %; {:.0} % of the speed across the \
         line of sight; {:.1} % of depths on a bound",
        100.0 * c.structure,
        100.0 * c.transverse,
        100.0 * c.at_bounds
    );
    if c.trusted {
        println!("  the lift passes its checks (its distance still rests on v_target)");
    }
    for r in &c.reasons {
        println!("  NOT TO BE TRUSTED: {r}");
    }
}
