use clap::Parser;

fn main() {
    // A panic is a bug; still, the user sees one line and a non-zero exit, not a backtrace.
    std::panic::set_hook(Box::new(|info| {
        let msg = info
            .payload()
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| info.payload().downcast_ref::<String>().cloned())
            .unwrap_or_default();
        let loc = info
            .location()
            .map(|l| format!(" at {l}"))
            .unwrap_or_default();
        eprintln!("error: internal error{loc}: {}", msg.replace('\n', " "));
    }));
    let cli = herdfit::cli::Cli::parse();
    if let Err(e) = herdfit::cli::run(cli) {
        eprintln!("error: {e}");
        std::process::exit(1);
    }
}
