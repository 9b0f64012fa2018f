//! The library's jobs (a config with its files, serde, `deny_unknown_fields`) run from Python
//! dicts: `run_job(kind, job, progress)` deserialises the dict into the job, runs it with the GIL
//! released and returns what the CLI would print; `job_defaults(kind)` gives the defaults.

use crate::errors::{from_serde, to_py};
use crate::progress::PyProgress;
use herdfit::herd::ablate::{self, AblateJob};
use herdfit::herd::author::job::AuthorJob;
use herdfit::herd::fit::{self, FitJob};
use herdfit::herd::gradcheck::GradcheckJob;
use herdfit::herd::import_tracks::{import_tracks, ImportTracksJob};
use herdfit::herd::synth::{write_clip, SynthJob};
use herdfit::herd::validate::{zone_report, ValidateJob};
use herdfit::progress::Progress;
use pyo3::prelude::*;
use serde::de::DeserializeOwned;

/// The job kinds `run_job` knows.
const KINDS: &[&str] = &[
    "fit",
    "validate",
    "ablate",
    "import_tracks",
    "synth",
    "author",
    "gradcheck",
];

fn unknown_kind(py: Python<'_>, kind: &str) -> PyErr {
    to_py(
        py,
        herdfit::Error::config(
            "kind",
            format!("'{kind}' is not one of {}", KINDS.join(", ")),
        ),
        None,
    )
}

/// Runs `job` (a dict) as the library job `kind`; returns its summary text.
#[pyfunction]
#[pyo3(signature = (kind, job, progress=None))]
fn run_job(
    py: Python<'_>,
    kind: &str,
    job: &Bound<'_, PyAny>,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let mut prog = PyProgress::new(progress);
    match kind {
        "fit" => {
            let j: FitJob = de(py, kind, job)?;
            detached(py, &mut prog, |p| match j.zones {
                Some(_) => fit::zone_job::run_zones(&j, p).map(|s| s.to_string()),
                None => fit::job::run(&j, p).map(|s| s.to_string()),
            })
        }
        "validate" => {
            let j: ValidateJob = de(py, kind, job)?;
            detached(py, &mut prog, |p| zone_report::run_either(&j, p))
        }
        "ablate" => {
            let j: AblateJob = de(py, kind, job)?;
            detached(py, &mut prog, |p| ablate::zoned::run_either(&j, p))
        }
        "import_tracks" => {
            let j: ImportTracksJob = de(py, kind, job)?;
            detached(py, &mut prog, |_| import_tracks(&j).map(|s| s.to_string()))
        }
        "synth" => {
            let j: SynthJob = de(py, kind, job)?;
            detached(py, &mut prog, |p| {
                write_clip(&j, p).map(|s| synth_summary(&s))
            })
        }
        "author" => {
            let j: AuthorJob = de(py, kind, job)?;
            detached(py, &mut prog, |p| {
                herdfit::herd::author::job::run(&j, p).map(|s| s.to_string())
            })
        }
        "gradcheck" => {
            let j: GradcheckJob = de(py, kind, job)?;
            detached(py, &mut prog, |p| {
                herdfit::herd::gradcheck::run(&j, p).map(|r| r.to_string())
            })
        }
        _ => Err(unknown_kind(py, kind)),
    }
}

/// The defaults of the job `kind`, as a dict (the keys its dict may hold).
#[pyfunction]
fn job_defaults<'py>(py: Python<'py>, kind: &str) -> PyResult<Bound<'py, PyAny>> {
    let value = match kind {
        "fit" => serde_json::to_value(FitJob::default()),
        "validate" => serde_json::to_value(ValidateJob::default()),
        "ablate" => serde_json::to_value(AblateJob::default()),
        "import_tracks" => {
            serde_json::to_value(herdfit::herd::import_tracks::ImportTracksConfig::default())
        }
        "synth" => serde_json::to_value(SynthJob::default()),
        "author" => serde_json::to_value(AuthorJob::default()),
        "gradcheck" => serde_json::to_value(GradcheckJob::default()),
        _ => return Err(unknown_kind(py, kind)),
    }
    .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("internal error: {e}")))?;
    Ok(pythonize::pythonize(py, &value)?)
}

/// `job` as the config `T`; an unknown or missing key → ConfigError naming it.
fn de<T: DeserializeOwned>(py: Python<'_>, kind: &str, job: &Bound<'_, PyAny>) -> PyResult<T> {
    pythonize::depythonize(job).map_err(|e| from_serde(py, kind, e))
}

/// Runs `f` with the GIL released, reporting to `prog`; errors become the package's exceptions.
fn detached<F>(py: Python<'_>, prog: &mut PyProgress, f: F) -> PyResult<String>
where
    F: FnOnce(&mut dyn Progress) -> herdfit::Result<String> + Send,
{
    let r = py.detach(|| f(&mut *prog));
    r.map_err(|e| to_py(py, e, Some(prog)))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(run_job, m)?)?;
    m.add_function(wrap_pyfunction!(job_defaults, m)?)?;
    Ok(())
}

/// What a synthetic clip holds, in a line.
fn synth_summary(s: &herdfit::herd::synth::Synth) -> String {
    let agents = s.frames.first().map_or(0, |f| f.len());
    format!(
        "synthetic clip: {} frames of {agents} agents\n",
        s.frames.len()
    )
}
