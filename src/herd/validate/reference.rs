//! The reference implementation's measures in a validation (`validate --measures reference`,
//! [`crate::measure::reference`]) and the open boundary's account: per set, the five measures
//! over the frames after the start (the start is drawn from the video, as the reference's logs
//! start after it), averaged over the seeds, and a per-frame log in the reference's own format
//! (`errorlog-<set>.txt`), so a run can be put line by line beside its `ErrorLog/*.txt`.

use super::{stat, Report, SetReport, SimRun, Stat};
use crate::data::ClipFields;
use crate::measure::reference::{
    reference_frame, target_velocity, RefFrame, LOG_HEADER, REFERENCE_MEASURES,
};
use serde::Serialize;

/// Which measures a validation reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Measures {
    /// herdfit's own (paper §7.1.2 on the fields, coarse-grid errors).
    #[default]
    Herdfit,
    /// herdfit's own and, beside them, the reference implementation's.
    Reference,
}

enum_names!(Measures { Herdfit = "herdfit", Reference = "reference" });

/// One of the reference's measures for one set: target (the video), simulation and error, each
/// mean ± STD over frames and seeds (density and velocity are errors only).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RefRow {
    pub measure: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target: Option<Stat>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub simulation: Option<Stat>,
    pub error: Stat,
}

/// A set's reference measures.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RefReport {
    pub rows: Vec<RefRow>,
    /// Per frame after the start, the seeds' mean of every value of the reference's log line.
    pub per_frame: Vec<[f64; 11]>,
    /// Per seed, the mean over the frames of each of the five errors.
    pub seed_errors: Vec<[f64; 5]>,
}

impl RefReport {
    /// The mean of one measure's error.
    pub fn error(&self, measure: &str) -> f64 {
        self.rows
            .iter()
            .find(|r| r.measure == measure)
            .map_or(f64::NAN, |r| r.error.mean)
    }

    /// The per-frame log in the reference's format (the seeds' means, frames numbered from 1
    /// after the start).
    pub fn log(&self) -> String {
        let mut s = String::from(LOG_HEADER);
        s.push('\n');
        for (k, v) in self.per_frame.iter().enumerate() {
            s.push_str(&format!("{}", k + 1));
            for x in v {
                s.push_str(&format!(" {x:.4}"));
            }
            s.push('\n');
        }
        s
    }
}

/// The reference's measures of a set's runs over frames `start..` of `clip` (each run's frame
/// 0 is `start`, which is skipped).
pub fn reference_of(clip: &ClipFields, start: usize, runs: &[SimRun]) -> RefReport {
    let frames = runs.first().map_or(0, |r| r.frames.len());
    let targets: Vec<Vec<[f64; 2]>> = (1..frames)
        .map(|k| target_velocity(clip, start + k))
        .collect();
    let mut all: Vec<Vec<RefFrame>> = Vec::with_capacity(runs.len());
    for run in runs {
        all.push(
            (1..frames)
                .map(|k| reference_frame(clip, start + k, &run.frames[k], &targets[k - 1]))
                .collect(),
        );
    }
    let mut errs: Vec<Vec<f64>> = vec![Vec::new(); 5];
    let (mut tgt, mut sim): (Vec<Vec<f64>>, Vec<Vec<f64>>) =
        (vec![Vec::new(); 3], vec![Vec::new(); 3]);
    let w = 1.0 / runs.len().max(1) as f64;
    let mut per_frame = vec![[0.0f64; 11]; frames.saturating_sub(1)];
    let mut seed_errors = Vec::with_capacity(runs.len());
    for frs in &all {
        let mut means = [0.0f64; 5];
        let mut counts = [0.0f64; 5];
        for (k, fr) in frs.iter().enumerate() {
            let e = fr.errors();
            for m in 0..5 {
                errs[m].push(e[m]);
                if e[m].is_finite() {
                    means[m] += e[m];
                    counts[m] += 1.0;
                }
            }
            let pairs = [fr.polarization, fr.angular_momentum, fr.aspect_ratio];
            for (j, p) in pairs.iter().enumerate() {
                tgt[j].push(p[0]);
                sim[j].push(p[1]);
            }
            let line = [
                e[0],
                e[1],
                pairs[0][0],
                pairs[0][1],
                e[2],
                pairs[1][0],
                pairs[1][1],
                e[3],
                pairs[2][0],
                pairs[2][1],
                e[4],
            ];
            for (a, b) in per_frame[k].iter_mut().zip(line) {
                *a += w * b;
            }
        }
        seed_errors.push(std::array::from_fn(|m| means[m] / counts[m].max(1.0)));
    }
    let rows = REFERENCE_MEASURES
        .iter()
        .enumerate()
        .map(|(m, name)| RefRow {
            measure: name.to_string(),
            target: (m >= 2).then(|| stat(&tgt[m - 2])),
            simulation: (m >= 2).then(|| stat(&sim[m - 2])),
            error: stat(&errs[m]),
        })
        .collect();
    RefReport {
        rows,
        per_frame,
        seed_errors,
    }
}

/// The report's sections on the open boundary and the reference's measures (empty when the
/// clip is closed and the reference's measures were not asked for).
pub fn markdown(r: &Report) -> String {
    let mut s = String::new();
    if let Some(b) = &r.boundary {
        let v = &b.video_count;
        let vmean = v.iter().sum::<f64>() / v.len().max(1) as f64;
        s.push_str(&format!(
            "## Open boundary\n\nThe clip's view is open: {} entry cell(s) and {} exit cell(s) on the grid's edge (`boundary.json`), from the video's flux across it. Agents that leave the grid are removed; the shortfall against the video's count enters at the entry cells, never inside the view. The video holds {vmean:.1} animals on average in the held-out frames.\n\n| set | entered per run | left per run (left, right, bottom, top) | count in view, mean | largest count difference |\n|---|---:|---|---:|---:|\n",
            b.gates.entries.len(),
            b.gates.exits.len()
        ));
        for set in &r.sets {
            if let Some(p) = &set.population {
                let m = p.count.iter().sum::<f64>() / p.count.len().max(1) as f64;
                s.push_str(&format!(
                    "| {} | {:.1} | {:.1}, {:.1}, {:.1}, {:.1} | {m:.1} | {:.1} % |\n",
                    set.name,
                    p.entered,
                    p.left[0],
                    p.left[1],
                    p.left[2],
                    p.left[3],
                    100.0 * p.worst_deviation(v)
                ));
            }
        }
        s.push_str("\nPlot: `count.png` (animals in view, video and simulation).\n\n");
    }
    let with_ref: Vec<&SetReport> = r.sets.iter().filter(|s| s.reference.is_some()).collect();
    if with_ref.is_empty() {
        return s;
    }
    s.push_str("## The reference implementation's measures\n\nHerdFromVideo's `ErrorDensity`, `ErrorVelocity`, `ErrorPolarization`, `ErrorAngularMomentum` and `ErrorAspectRatio` on the agents (density and velocity errors on the clip's own grid, the velocity target propagated into empty cells), over the frames after the start; targets of polarization and angular momentum from the video's own frame measures when the clip carries them. Per-frame logs in the reference's format: `errorlog-<set>.txt`.\n\n| measure |");
    for set in &with_ref {
        s.push_str(&format!(
            " {} target | {} simulation | {} error |",
            set.name, set.name, set.name
        ));
    }
    s.push_str("\n|---|");
    for _ in &with_ref {
        s.push_str("---:|---:|---:|");
    }
    s.push('\n');
    let f = |x: &Option<Stat>| match x {
        Some(st) => format!("{:.4} ± {:.4}", st.mean, st.std),
        None => "—".into(),
    };
    for (m, name) in REFERENCE_MEASURES.iter().enumerate() {
        s.push_str(&format!("| {name} |"));
        for set in &with_ref {
            let row = &set.reference.as_ref().expect("filtered").rows[m];
            s.push_str(&format!(
                " {} | {} | {:.4} ± {:.4} |",
                f(&row.target),
                f(&row.simulation),
                row.error.mean,
                row.error.std
            ));
        }
        s.push('\n');
    }
    s.push('\n');
    s
}
