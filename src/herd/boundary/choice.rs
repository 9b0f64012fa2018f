//! How a run treats the edge of a clip's grid: the derived gates, closed, or a file
//! (`--boundary auto|closed|FILE`).

use super::gates_of_clip;
use crate::data::boundary::Gates;
use crate::data::ClipFields;
use crate::error::Result;
use serde::Serialize;

/// How a run treats the edge of a clip's grid (`--boundary`; the key `boundary`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum BoundaryChoice {
    /// The gates derived from the clip's flux ([`gates_of_clip`]): closed when nothing crosses.
    #[default]
    Auto,
    /// Closed whatever the clip shows: nothing enters or leaves.
    Closed,
    /// The gates of a `herdfit.boundary/1` file.
    File(std::path::PathBuf),
}

impl BoundaryChoice {
    /// The gates of `clip` under this choice; a file's errors name it.
    pub fn gates(&self, clip: &ClipFields) -> Result<Gates> {
        match self {
            BoundaryChoice::Auto => Ok(gates_of_clip(clip)),
            BoundaryChoice::Closed => Ok(Gates::closed()),
            BoundaryChoice::File(p) => {
                let g = Gates::load(p)?;
                g.check(clip.meta.nx, clip.meta.ny, &clip.obstacles)
                    .map_err(|e| e.in_file(p))?;
                Ok(g)
            }
        }
    }
}

impl std::str::FromStr for BoundaryChoice {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "" => Err("expected auto, closed or a herdfit.boundary/1 file".into()),
            "auto" => Ok(BoundaryChoice::Auto),
            "closed" => Ok(BoundaryChoice::Closed),
            p => Ok(BoundaryChoice::File(p.into())),
        }
    }
}

impl std::fmt::Display for BoundaryChoice {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            BoundaryChoice::Auto => write!(f, "auto"),
            BoundaryChoice::Closed => write!(f, "closed"),
            BoundaryChoice::File(p) => write!(f, "{}", p.display()),
        }
    }
}

impl Serialize for BoundaryChoice {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> serde::Deserialize<'de> for BoundaryChoice {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = String::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}
