//! Parameter-set bundles (`herdfit.param-sets/1`, DESIGN §6): named parameter sets, each with
//! the zone it was fitted on. A zone fit ([`crate::herd::fit`]) writes one; an author scene's
//! region ([`crate::herd::author`]), a zoned validation and `synth --params` read one.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Schema tag of a parameter-set bundle.
pub const PARAM_SETS_SCHEMA: &str = "herdfit.param-sets/1";

/// One named parameter set of a bundle, with the zone it was fitted on (its polygon or mask
/// colour, and its fixed speed).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedSet {
    pub name: String,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub polygon: Vec<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<f64>,
    pub params: crate::herd::params::Params,
}

/// A parameter-set bundle (`herdfit.param-sets/1`): what a zone fit writes, and what an author
/// scene's region names a set of (`regions[k].params` the bundle, `regions[k].set` the name).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamSets {
    pub schema: String,
    /// The mask image of the zones the sets were fitted on (zones by colour), if any.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<PathBuf>,
    pub sets: Vec<NamedSet>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<serde_json::Value>,
}

impl ParamSets {
    /// Reads a bundle; every set is validated (errors name the file and the set).
    pub fn load(path: &Path) -> Result<ParamSets> {
        let text = crate::data::atomic::read_input_text(path)?;
        let b: ParamSets = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a parameter-set bundle: {e}")))?;
        if b.schema != PARAM_SETS_SCHEMA {
            return Err(Error::file(
                path,
                format!("schema: '{}' is not {PARAM_SETS_SCHEMA}", b.schema),
            ));
        }
        for (k, s) in b.sets.iter().enumerate() {
            s.params
                .validate()
                .map_err(|e| Error::file(path, format!("sets[{k}] ('{}'): {e}", s.name)))?;
        }
        Ok(b)
    }

    /// The set named `name`, or an error listing the names.
    pub fn get(&self, name: &str) -> std::result::Result<&crate::herd::params::Params, String> {
        self.sets
            .iter()
            .find(|s| s.name == name)
            .map(|s| &s.params)
            .ok_or_else(|| {
                let names: Vec<&str> = self.sets.iter().map(|s| s.name.as_str()).collect();
                format!("'{name}' is not in the bundle ({})", names.join(", "))
            })
    }

    /// Writes the bundle atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let json = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Internal(format!("serialising a bundle: {e}")))?;
        crate::data::atomic::write_atomic(path, format!("{json}\n").as_bytes())
    }
}
