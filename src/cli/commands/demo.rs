//! `herdfit demo`: the built-in walk-through ([`crate::herd::demo`]).

use crate::cli::paths::OutDirAll;
use crate::cli::Bars;
use crate::data::atomic::{cleanup::user_facing, AtomicDir};
use crate::error::Result;
use crate::herd::demo::{demo, DEMO_HEADER};
use clap::Args;

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/demo")]
    pub out: OutDirAll,
}

pub fn exec(a: DemoArgs) -> Result<()> {
    println!("{DEMO_HEADER}");
    // One folder written whole: the walk-through reads back what it wrote (the video it extracts,
    // the clip it fits), so it works inside the folder's temporary sibling; printed paths name
    // the folder the user gave.
    let dir = AtomicDir::create(&a.out)?;
    let out = dir.root().to_path_buf();
    let show = |s: String| println!("{}", user_facing(&s));
    let summary = demo(&out, &mut Bars::default())?;
    print!("{}", user_facing(&summary.to_string()));
    show(crate::flock::demo(&out, &mut Bars::default())?.to_string());
    println!();
    show(crate::lift::demo(&out, &mut Bars::default())?.to_string());
    println!();
    show(crate::crowd::demo(&out.join("crowd"), &mut Bars::default())?.to_string());
    // The files record where the clips they came from are: the folder the user gave.
    dir.name_the_target_in_text_files()?;
    dir.commit()
}
