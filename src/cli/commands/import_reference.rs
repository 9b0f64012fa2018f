//! `herdfit import-reference`: the public extractor's text files → a clip folder.

use crate::cli::paths::{InPrefix, OutDir};
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
}

pub fn exec(a: ImportArgs) -> Result<()> {
    let clip = import_reference(&a.prefix)?;
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
