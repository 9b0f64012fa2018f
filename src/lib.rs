//! herdfit: learn how animal groups move from video and replay that behaviour anywhere.
//!
//! The pipeline (see `ARCHITECTURE.md`): clip fields → fit → parameter set → simulate/author.
//! Subsystems live in their own folders ([`herd`]: the herd model of *Herds From Video*); shared
//! layers beside them: [`data`] (on-disk formats), [`measure`] (emergent measures and field
//! comparisons), [`optim`] (optimisers), [`video`] (OpenCV), and the command-line interface
//! ([`cli`]).

/// `Display` and `FromStr` of a unit enum by the names given: the names its settings files and
/// the command line use (serde's `rename_all = "lowercase"` names, written once here).
macro_rules! enum_names {
    ($ty:ident { $($variant:ident = $name:literal),+ $(,)? }) => {
        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(match self {
                    $($ty::$variant => $name,)+
                })
            }
        }

        impl std::str::FromStr for $ty {
            type Err = String;
            fn from_str(s: &str) -> std::result::Result<Self, String> {
                match s {
                    $($name => Ok($ty::$variant),)+
                    _ => Err(format!("'{s}' is not one of {}", [$($name),+].join(", "))),
                }
            }
        }
    };
}

pub mod backend;
pub mod cli;
pub mod crowd;
pub mod data;
pub mod error;
pub mod flock;
pub mod herd;
pub mod lift;
pub mod limits;
pub mod measure;
pub mod optim;
pub mod plot;
pub mod progress;
#[cfg(feature = "video")]
pub mod video;

pub use error::{Error, Result};
