//! `herdfit demo`: the built-in walk-through ([`crate::herd::demo`]).

use crate::cli::Bars;
use crate::error::Result;
use crate::herd::demo::{demo, DEMO_HEADER};
use clap::Args;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/demo")]
    pub out: PathBuf,
}

pub fn exec(a: DemoArgs) -> Result<()> {
    println!("{DEMO_HEADER}");
    let summary = demo(&a.out, &mut Bars::default())?;
    print!("{summary}");
    println!("{}", crate::flock::demo(&a.out, &mut Bars::default())?);
    println!();
    println!("{}", crate::lift::demo(&a.out, &mut Bars::default())?);
    println!();
    println!(
        "{}",
        crate::crowd::demo(&a.out.join("crowd"), &mut Bars::default())?
    );
    Ok(())
}
