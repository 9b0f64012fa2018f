//! Flag parsing shared by the commands: value parsers (pairs, ranges, grids, colours) and the
//! flag groups several verbs take.

use crate::herd::simulate::HerdSource;
use clap::Args;
use std::path::{Path, PathBuf};

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

/// `out` with its extension replaced by `suffix` (`params.json` → `params.log.csv`).
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "params".into());
    out.with_file_name(format!("{stem}{suffix}"))
}

/// Where the initial herd comes from.
#[derive(Args, Debug, Clone)]
#[group(required = false, multiple = false)]
pub struct HerdArgs {
    /// Initial state: CSV with columns id,x,y,vx,vy (BL, BL/s).
    #[arg(long, value_name = "INIT.csv")]
    pub init: Option<PathBuf>,
    /// A built-in random herd of N agents (one per 2 BL², heading +x ± 20°) instead of --init.
    #[arg(long, value_name = "N")]
    pub agents: Option<usize>,
}

impl HerdArgs {
    /// The herd source given, if any.
    pub fn source(&self) -> Option<HerdSource> {
        match (&self.init, self.agents) {
            (Some(p), _) => Some(HerdSource::Init(p.clone())),
            (None, Some(n)) => Some(HerdSource::Agents(n)),
            (None, None) => None,
        }
    }
}
