fn main() {
    // Die quietly on a closed pipe (`herdfit fields-info CLIP | head`), like other Unix tools,
    // instead of failing a print.
    #[cfg(unix)]
    // SAFETY: restoring the default disposition of SIGPIPE before any thread starts.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
        // A file-size limit (`ulimit -f`) makes a write fail (EFBIG) and the run report it and
        // leave nothing behind, instead of killing the process mid-file.
        libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
    }
    // Temporary siblings go with the process on SIGINT/SIGTERM; outputs never replace inputs.
    herdfit::data::atomic::install_signal_cleanup();
    herdfit::data::atomic::guard_inputs();
    // `-` as an output: data keep standard output, messages go to standard error.
    if std::env::args_os().skip(1).any(|a| a == "-") {
        herdfit::data::atomic::take_stdout();
    }
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
    let matches = match <herdfit::cli::Cli as clap::CommandFactory>::command().try_get_matches() {
        Ok(m) => m,
        Err(e) => {
            use clap::error::ErrorKind::{DisplayHelp, DisplayVersion};
            if matches!(e.kind(), DisplayHelp | DisplayVersion)
                || e.kind() == clap::error::ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand
            {
                e.exit();
            }
            // Usage errors: clap's message folded onto one line (no usage block), exit 2.
            let text = e.render().to_string();
            let msg: Vec<&str> = text
                .lines()
                .take_while(|l| !l.trim().is_empty())
                .map(str::trim)
                .collect();
            eprintln!("{}", msg.join(" "));
            std::process::exit(2);
        }
    };
    if let Err(e) = herdfit::cli::execute(&matches) {
        // An error raised inside a temporary sibling names the output it stands for.
        let msg = herdfit::data::atomic::cleanup::user_facing(&e.to_string());
        eprintln!("error: {msg}");
        std::process::exit(1);
    }
}
