//! `herdfit import-reference`: the public extractor's text files → a clip folder.

use crate::cli::paths::{InPrefix, OutDir};
use crate::data::clip::check_dir_spread;
use crate::data::reference::import_reference;
use crate::error::Result;
use clap::Args;

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// Prefix of the three files: PREFIX_data_meta.txt, PREFIX_data_frame.txt, PREFIX_data_cell.txt.
    #[arg(value_name = "PREFIX")]
    pub prefix: InPrefix,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: OutDir,
    /// The spread of the animals' directions (rad² about their mean) when the files do not
    /// measure it, e.g. a still such as the seals (no per-cell angles): E_var (eq. 8) then
    /// targets it instead of the files' zeros, which would ask every cell to align. Set by
    /// inspection: randomly aligned animals π²/3 ≈ 3.29; the paper's seals 3000 deg² ≈ 0.914.
    #[arg(long, value_name = "V")]
    pub dir_variance: Option<f64>,
}

pub fn exec(a: ImportArgs) -> Result<()> {
    let mut clip = import_reference(&a.prefix)?;
    if let Some(v) = a.dir_variance {
        check_dir_spread("--dir-variance", v)?;
        clip.meta.dir_spread = Some(v);
    }
    clip.save(&a.out, &[])?;
    println!(
        "import-reference: {} frames, {}×{} cells of {:.4} BL, {:.3} fps; wrote {}",
        clip.frames(),
        clip.meta.nx,
        clip.meta.ny,
        clip.meta.cell_size,
        clip.meta.fps,
        a.out.display()
    );
    Ok(())
}
