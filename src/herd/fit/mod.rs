//! Fitting the 12 force parameters to clip fields by gradient descent through unrolled steps
//! (paper §6, DESIGN §5), then the speed model from the clip (§6.2).
//!
//! An epoch starts a herd from the fields of the first frame of the range and walks through the
//! frames in windows of W steps. Each step is first *planned* without gradient — perception and
//! roles (leaders follow the clip's velocity field propagated into empty cells), OU noise, each
//! agent's cell and the target direction U of every cell (eq. 10–11) — then *evaluated* as tensor
//! ops; the window's mean loss E_mean + λ_var E_var is back-propagated through its W steps to θ,
//! the optimiser updates θ, and the state is detached. Between windows agents that left the grid
//! are removed and, when the density error exceeds a threshold or the clip has more agents than
//! the simulation, the population is rebalanced from the fields.

pub mod anchor;
pub mod checkpoint;
pub mod choose;
pub mod config;
pub mod global;
mod herds;
pub mod identify;
pub mod job;
pub mod log;
pub mod loss;
pub mod plan;
pub mod run;
pub mod still;
pub mod target;
pub mod zone_job;

pub use crate::herd::eval::{clip_model, evaluate};
pub use crate::herd::guidance::{
    check_guidance_scale, guidance_field, guidance_fields, GUIDANCE_SCALE,
};
pub use crate::herd::start::{init_herd, population_control, settle, start_herd, Settle};
pub use crate::optim::{OptState, Optimizer};
pub use checkpoint::{update, Checkpoint, CheckpointDir};
pub use config::{FitConfig, GlobalPhase, LossKind, ALIGNMENT};
pub use global::{fit_global, GlobalReport};
pub use identify::{identify, UncertaintyConfig};
pub use job::{FitJob, FitSummary};
pub use log::{log_csv, write_log, LogRow};
pub use loss::{ensemble_loss, fields_loss};
pub use plan::{plan_step, window_loss};
pub use run::{fit, fit_clips, fit_zones, loss_of, FitResult, ZoneFitResult};
