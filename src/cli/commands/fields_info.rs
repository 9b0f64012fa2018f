//! `herdfit fields-info`: a clip → [`FieldsInfo`] → its table (and JSON).

use crate::cli::paths::{InDir, OutFile};
use crate::data::atomic::check_writable;
use crate::data::ClipFields;
use crate::error::Result;
use crate::measure::info::FieldsInfo;
use clap::Args;

#[derive(Args, Debug)]
pub struct FieldsInfoArgs {
    #[arg(value_name = "CLIP/")]
    pub clip: InDir,
    /// Also write the summary and per-frame measures as JSON.
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<OutFile>,
}

pub fn exec(a: FieldsInfoArgs) -> Result<()> {
    let clip = ClipFields::load(&a.clip)?;
    if let Some(j) = &a.json {
        check_writable(j)?;
    }
    let info = FieldsInfo::new(&a.clip.display().to_string(), &clip);
    print!("{info}");
    if let Some(j) = &a.json {
        info.save(j)?;
    }
    Ok(())
}
