//! One finiteness rule for every number on the command line (issue #47): after parsing and before
//! the verb runs, every floating-point value of the verb's flags (alone, or in a pair or triple
//! such as `--guidance DX,DY` or `--position X,Y,Z`) must be finite — NaN never, ±inf only for the
//! flags that give it a meaning ([`INFINITE_OK`]). The error names the flag, in the words every
//! other finiteness check uses ([`crate::limits::not_finite`]). Ranges are the verbs' own (their
//! configs' `check()`), named by the same flags.

use crate::error::{Error, Result};
use clap::ArgMatches;

/// Flags (by clap id) where `inf` means something (`--guidance-scale inf`: the herd's mean
/// direction everywhere).
pub const INFINITE_OK: [&str; 1] = ["guidance_scale"];

/// Every floating-point value of `m`'s arguments: `(argument, value)`.
fn floats(cmd: &clap::Command, m: &ArgMatches) -> Vec<(String, String, f64)> {
    let mut out = Vec::new();
    for a in cmd.get_arguments() {
        let id = a.get_id().as_str();
        let name = super::paths::arg_name(a);
        let mut push = |v: f64| out.push((id.to_string(), name.clone(), v));
        if let Ok(Some(v)) = m.try_get_many::<f64>(id) {
            v.for_each(|x| push(*x));
        } else if let Ok(Some(v)) = m.try_get_many::<f32>(id) {
            v.for_each(|x| push(*x as f64));
        } else if let Ok(Some(v)) = m.try_get_many::<(f64, f64)>(id) {
            v.for_each(|x| {
                push(x.0);
                push(x.1)
            });
        } else if let Ok(Some(v)) = m.try_get_many::<[f64; 3]>(id) {
            v.for_each(|x| x.iter().for_each(|c| push(*c)));
        }
    }
    out
}

/// Refuses a non-finite value of any floating-point flag of the verb `m` runs.
pub fn check(cmd: &clap::Command, m: &ArgMatches) -> Result<()> {
    let (cmd, m) = super::paths::leaf(cmd, m);
    for (id, name, v) in floats(cmd, m) {
        if v.is_nan() || (v.is_infinite() && !INFINITE_OK.contains(&id.as_str())) {
            return Err(Error::invalid(format!(
                "{name}: {}",
                crate::limits::not_finite(v)
            )));
        }
    }
    Ok(())
}
