//! Flag parsing shared by the commands: value parsers (pairs, ranges, grids, colours) and the
//! flag groups several verbs take.

use crate::backend::Compute;
use crate::cli::paths::{InFile, OutFile};
use crate::error::Error;
use crate::herd::boundary::BoundaryChoice;
use crate::herd::simulate::{HerdSource, RunFiles};
use clap::Args;
use std::path::Path;

/// Two values of type `T` from `s` cut in two by `split` (each trimmed); `form` names the
/// expected shape and `what` one value in the messages.
fn parse_two<'a, T: std::str::FromStr>(
    s: &'a str,
    split: impl Fn(&'a str) -> Option<(&'a str, &'a str)>,
    form: &str,
    what: &str,
) -> std::result::Result<(T, T), String> {
    let (a, b) = split(s).ok_or_else(|| format!("expected {form}, got '{s}'"))?;
    let p = |t: &str| {
        t.trim()
            .parse::<T>()
            .map_err(|_| format!("'{t}' is not {what}"))
    };
    Ok((p(a)?, p(b)?))
}

/// `a..b`, frame indices (b exclusive).
pub fn parse_range(s: &str) -> std::result::Result<(usize, usize), String> {
    parse_two(s, |s| s.split_once(".."), "a..b", "a frame index")
}

/// `NXxNY`, cell counts (at least one each way).
pub fn parse_grid(s: &str) -> std::result::Result<(usize, usize), String> {
    let (nx, ny): (usize, usize) =
        parse_two(s, |s| s.split_once(['x', 'X']), "NXxNY", "a cell count")?;
    if nx == 0 || ny == 0 {
        return Err("the grid needs at least one cell each way".into());
    }
    Ok((nx, ny))
}

/// `DX,DY`, a finite non-zero direction.
pub fn parse_pair(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b): (f64, f64) = parse_two(s, |s| s.split_once(','), "DX,DY", "a number")?;
    if !(a.is_finite() && b.is_finite()) || (a == 0.0 && b == 0.0) {
        return Err("the direction must be finite and non-zero".into());
    }
    for v in [a, b] {
        if v.abs() > crate::limits::MAX_COORD {
            return Err(crate::limits::beyond(v, crate::limits::MAX_COORD));
        }
    }
    Ok((a, b))
}

/// `R,G,B`, each 0..=255.
pub fn parse_rgb(s: &str) -> std::result::Result<[u8; 3], String> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != 3 {
        return Err(format!("expected R,G,B, got '{s}'"));
    }
    let mut out = [0u8; 3];
    for (o, t) in out.iter_mut().zip(v) {
        *o = t
            .trim()
            .parse()
            .map_err(|_| format!("'{t}' is not a value in 0..=255"))?;
    }
    Ok(out)
}

/// Where the initial herd comes from.
#[derive(Args, Debug, Clone)]
#[group(required = false, multiple = false)]
pub struct HerdArgs {
    /// Initial state: CSV with columns id,x,y,vx,vy (BL, BL/s).
    #[arg(long, value_name = "INIT.csv")]
    pub init: Option<InFile>,
    /// A built-in random herd of N agents (one per 2 BL², heading +x ± 20°) instead of --init.
    #[arg(long, value_name = "N")]
    pub agents: Option<usize>,
}

/// The files of a run (`simulate`, `gradcheck`): parameters, herd, decisions recorded or
/// replayed.
#[derive(Args, Debug, Clone)]
pub struct RunArgs {
    /// Parameter set (herdfit.params/1 JSON); the built-in default set when omitted.
    #[arg(long, value_name = "P.json")]
    pub params: Option<InFile>,
    #[command(flatten)]
    pub herd: HerdArgs,
    /// Write the run's decisions (perception, roles, noise) to this file (JSON), to replay them.
    #[arg(long, value_name = "REC.json")]
    pub record: Option<OutFile>,
    /// Replay the decisions of a recorded run instead of computing them.
    #[arg(long, value_name = "REC.json", conflicts_with = "record")]
    pub replay: Option<InFile>,
}

impl RunArgs {
    /// The library's [`RunFiles`].
    pub fn files(self) -> RunFiles {
        RunFiles {
            params: self.params.map(Into::into),
            herd: self.herd.source(),
            record: self.record.map(Into::into),
            replay: self.replay.map(Into::into),
        }
    }
}

impl HerdArgs {
    /// The herd source given, if any.
    pub fn source(&self) -> Option<HerdSource> {
        match (&self.init, self.agents) {
            (Some(p), _) => Some(HerdSource::Init(p.clone().into())),
            (None, Some(n)) => Some(HerdSource::Agents(n)),
            (None, None) => None,
        }
    }
}

/// The values of an enum flag with their help, `(name, help)` (empty help: none); the library
/// type parses the name.
pub fn choice<T>(
    values: &'static [(&'static str, &'static str)],
) -> impl clap::builder::TypedValueParser<Value = T>
where
    T: std::str::FromStr<Err = String> + Clone + Send + Sync + 'static,
{
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(values.iter().map(|&(name, help)| {
        let v = PossibleValue::new(name);
        if help.is_empty() {
            v
        } else {
            v.help(help)
        }
    }))
    .try_map(|s: String| s.parse::<T>())
}

/// `--device`.
pub const DEVICES: &[(&str, &str)] = &[
    ("cpu", "burn's ndarray backend on this CPU (the default)"),
    (
        "gpu",
        "burn's wgpu backend (a build with the cargo feature `gpu`; f32); CUBECL_WGPU_DEFAULT_DEVICE picks the adapter, e.g. Cpu for a software Vulkan driver",
    ),
];

/// `--device`, on every verb that simulates the herd model.
#[derive(Args, Debug, Clone, Copy)]
pub struct DeviceArg {
    /// Where the model's tensors live (perception stays on the CPU).
    #[arg(long, value_parser = choice::<Compute>(DEVICES), default_value_t = Compute::Cpu)]
    pub device: Compute,
}

/// `--precision`.
pub const PRECISIONS: &[(&str, &str)] = &[("f32", ""), ("f64", "")];

/// `--optimizer`.
pub const OPTIMIZERS: &[(&str, &str)] = &[
    ("adam", "Adam (β₁ 0.9, β₂ 0.999, ε 1e-8)"),
    (
        "normalized",
        "The paper's normalised gradient step θ ← θ − lr · g/‖g‖",
    ),
    (
        "averaged",
        "The normalised step on a running mean of the gradients, scaled by how well they agree (about lr where they agree, a hundredth of it where they are noise)",
    ),
];

/// `--measures` of validate.
pub const MEASURES: &[(&str, &str)] = &[
    ("herdfit", "herdfit's own (paper §7.1.2 on the fields, coarse-grid errors)"),
    (
        "reference",
        "herdfit's own and, beside them, the reference implementation's (HerdFromVideo's HerdController.cs), with per-frame logs in its format",
    ),
];

/// `--loss` of ablate and gradcheck: the objectives themselves.
pub const LOSSES: &[(&str, &str)] = FIT_LOSSES.split_at(3).0;

/// `--loss` of fit: the objectives, and `auto`.
pub const FIT_LOSSES: &[(&str, &str)] = &[
    (
        "paper",
        "E_mean (eq. 7) + λ_var E_var (eq. 8) against the target field U (eq. 10–11)",
    ),
    (
        "fields",
        "Field matching: after every step, the simulated density and momentum fields (bilinear splatting of the agents and of their velocities) against the clip's, Σ(ρ' − Kρ)² / Σ(Kρ)² + Σ‖ρ'V' − K(ρV)‖² / Σ‖K(ρV)‖², plus λ_var E_var, where K blurs the clip's box-binned fields as splatting blurs points",
    ),
    (
        "ensemble",
        "Field matching of the *expected* simulated fields: the replicas' mean fields against the clip's, minus the replicas' own spread (an unbiased estimate of ‖E[ρ'] − ρ‖²), plus λ_var E_var. Needs --replicas ≥ 2",
    ),
    (
        "auto",
        "fields or paper, chosen on the fit's own frames: each fitted on the first half, the one whose set predicts the second half better (density + velocity error over --choice-seeds runs) is fitted on all of them. fields for a still, a zone fit or fewer than 2 × max(--window + 1, 4) frames",
    ),
];

/// `--objective` of gradcheck.
pub const OBJECTIVES: &[(&str, &str)] = &[
    (
        "herd",
        "Spread + mean heading of the default scenario's herd after T steps",
    ),
    (
        "loss",
        "The fit's loss (--loss: E_mean + λ E_var, eq. 7–8, or field matching, or the ensemble objective) over T steps on a clip",
    ),
];

/// The flag of a config key: `--key-with-dashes`, or the flag `renamed` gives it. A key inside a
/// table (`settle.eta`) has no flag and stays as it is.
pub fn flag(key: &str, renamed: &[(&str, &str)]) -> String {
    if let Some((_, f)) = renamed.iter().find(|(k, _)| *k == key) {
        return f.to_string();
    }
    if key.contains('.') {
        return key.to_string();
    }
    format!("--{}", key.replace('_', "-"))
}

/// A library error with its config keys named as this command's flags (ripgrep's rule: the
/// library names keys, the parser adds flags).
pub fn with_flags(e: Error, renamed: &[(&str, &str)]) -> Error {
    match e {
        Error::Config { file, err } => {
            let msg = err.render(&|k| flag(k, renamed));
            match file {
                Some(p) => Error::file(p, msg),
                None => Error::invalid(msg),
            }
        }
        other => other,
    }
}

/// [`with_flags`] for a command whose settings may come from a file: a bad value that `settings`
/// (the file's top-level keys) holds and `given(key)` says no flag overrode is named by the file
/// and its key (`extract.json: grid: must be ≥ 1`).
pub fn with_settings(
    e: Error,
    renamed: &[(&str, &str)],
    settings: Option<(&Path, &serde_json::Value)>,
    given: &dyn Fn(&str) -> bool,
) -> Error {
    match (e, settings) {
        (Error::Config { err, .. }, Some((path, file)))
            if file.get(&err.key).is_some() && !given(&err.key) =>
        {
            Error::file(path, err.to_string())
        }
        (e, _) => with_flags(e, renamed),
    }
}

/// `--boundary auto|closed|FILE` (issue #46) as the library's [`BoundaryChoice`]; a file named
/// there is an input of the run's plan ([`crate::cli::paths::InFileOrWord`]).
pub fn boundary(b: &crate::cli::paths::InFileOrWord) -> Result<BoundaryChoice, Error> {
    b.text()
        .parse()
        .map_err(|e: String| Error::invalid(format!("--boundary: {e}")))
}
