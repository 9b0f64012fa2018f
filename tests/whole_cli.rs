//! Issue #47: every verb keeps every promise, tested over the whole command line. The cases are
//! generated from clap's command table (`tests/whole_cli/table.rs`) and one or more working
//! invocations per verb (the baselines below), by `tests/whole_cli/engine.rs`: every output onto
//! every input, input sidecar and other output, onto devices, links, FIFOs and folders, onto a full
//! file system (as root), and hostile values (1e300, NaN, −1, inf; 10^9 for integers) for every
//! numeric flag. A verb or output flag with no baseline, or a path flag with no role, fails here.
//!
//! `every_verb_keeps_every_promise` prints its case count and time; the threads it runs cases on
//! are `HERDFIT_WHOLE_CLI_THREADS` (default: the machine's parallelism, at most 4).

#[path = "whole_cli/engine.rs"]
mod engine;
#[path = "whole_cli/fixture.rs"]
mod fixture;
#[path = "whole_cli/table.rs"]
mod table;

use clap::CommandFactory;
use engine::{Report, Subject};
use fixture::{fixture, BASELINES};
use std::path::PathBuf;
use std::time::Duration;

fn threads() -> usize {
    std::env::var("HERDFIT_WHOLE_CLI_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| {
            std::thread::available_parallelism()
                .map_or(2, |n| n.get())
                .min(4)
        })
}

fn herdfit_subject() -> Subject {
    Subject {
        program: PathBuf::from(env!("CARGO_BIN_EXE_herdfit")),
        verbs: table::verbs(herdfit::cli::Cli::command()),
        baselines: BASELINES
            .iter()
            .map(|(k, a)| {
                (
                    k.to_string(),
                    a.split_whitespace().map(str::to_string).collect(),
                )
            })
            .collect(),
        fixture: fixture().to_path_buf(),
        // The walk-through takes a minute: its refusals are tested, its run is not repeated.
        long_verbs: vec![("demo".into(), 1 << 20)],
        timeout: Duration::from_secs(60),
    }
}

fn print(name: &str, report: &Report) {
    let summary = format!(
        "{name}: {} cases in {:.0} s ({} accepted cleanly where a value may be legitimate), \
         {} failed",
        report.cases,
        report.seconds,
        report.accepted,
        report.failures.len()
    );
    // Past the test harness's capture (it takes only the print macros), so that the count shows
    // in `cargo test --workspace` and `.ci/run` without --nocapture.
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{summary}");
    for (k, n) in &report.by_kind {
        println!("  {k}: {n}");
    }
    for n in &report.notes {
        println!("  note: {n}");
    }
    for f in &report.failures {
        println!("FAIL {f}");
    }
}

#[test]
fn every_verb_keeps_every_promise() {
    let subject = herdfit_subject();
    let cmd = herdfit::cli::Cli::command();
    let report = engine::run(
        &subject,
        &cmd,
        &herdfit::cli::numbers::INFINITE_OK,
        threads(),
    );
    print("whole CLI", &report);
    assert!(
        report.failures.is_empty(),
        "{} of {} cases broke a promise (listed above)",
        report.failures.len(),
        report.cases
    );
    assert!(report.cases >= 1000, "only {} cases", report.cases);
}

/// A verb added without the policy: a program that writes its `--out` (and a sidecar) straight
/// away, with no declared plan, no checks of its numbers and no temporary names. The same engine,
/// given the verb's table and one baseline, must fail it for each broken promise.
#[test]
fn a_verb_that_writes_without_the_policy_fails_the_generated_test() {
    use herdfit::cli::paths::{InFile, OutTracks};
    let dir = tempfile::tempdir().unwrap();
    let fx = dir.path().join("fixture");
    std::fs::create_dir_all(&fx).unwrap();
    std::fs::write(fx.join("in.csv"), "frame,time,id,x,y\n0,0,0,1,2\n").unwrap();
    std::fs::write(fx.join("in.json"), "{\"fps\": 1}\n").unwrap();
    let prog = dir.path().join("rogue");
    std::fs::write(
        &prog,
        r#"#!/bin/sh
# rogue write INPUT --out OUT [--scale S] [--count N]: no plan, no checks, written in place.
shift
in=$1; shift
s=1
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out=$2; shift 2;; --out=*) out=${1#--out=}; shift;;
    --scale) s=$2; shift 2;; --scale=*) s=${1#--scale=}; shift;;
    --count) shift 2;; --count=*) shift;;
    *) shift;;
  esac
done
cat "$in" > "$out" || exit 1
echo "{\"scale\": $s}" > "${out%.csv}.json"
"#,
    )
    .unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&prog, std::fs::Permissions::from_mode(0o755)).unwrap();
    let cmd = clap::Command::new("rogue").subcommand(
        clap::Command::new("write")
            .arg(clap::Arg::new("input").value_parser(clap::value_parser!(InFile)))
            .arg(
                clap::Arg::new("out")
                    .long("out")
                    .value_parser(clap::value_parser!(OutTracks)),
            )
            .arg(
                clap::Arg::new("scale")
                    .long("scale")
                    .value_parser(clap::value_parser!(f64)),
            )
            .arg(
                clap::Arg::new("count")
                    .long("count")
                    .value_parser(clap::value_parser!(usize)),
            ),
    );
    let subject = Subject {
        program: prog,
        verbs: table::verbs(cmd.clone()),
        baselines: vec![(
            "write".into(),
            ["in.csv", "--out", "o.csv"].map(String::from).to_vec(),
        )],
        fixture: fx,
        long_verbs: Vec::new(),
        timeout: Duration::from_secs(20),
    };
    let report = engine::run(&subject, &cmd, &[], 2);
    print("rogue verb (must fail)", &report);
    let failed = |kind: &str| {
        report
            .failures
            .iter()
            .any(|f| f.starts_with(&format!("[{kind}]")))
    };
    for kind in ["onto an input", "onto a hostile target", "hostile number"] {
        assert!(failed(kind), "the rogue verb passed every '{kind}' case");
    }
    // Its output onto its own input: the input is destroyed and the run says nothing.
    assert!(
        report
            .failures
            .iter()
            .any(|f| f.contains("onto input in.json") && f.contains("accepted")),
        "{:#?}",
        report.failures
    );
    if engine::can_mount() {
        assert!(failed("full disk"), "the rogue verb passed the full disk");
    }
}

/// A new path flag typed as a plain `PathBuf` has no role: the generated test refuses the table.
#[test]
fn a_path_flag_without_a_role_fails_the_generated_test() {
    let cmd = herdfit::cli::Cli::command().mut_subcommand("simulate", |c| {
        c.arg(
            clap::Arg::new("dump")
                .long("dump")
                .value_parser(clap::value_parser!(std::path::PathBuf)),
        )
    });
    let subject = Subject {
        verbs: table::verbs(cmd.clone()),
        ..herdfit_subject()
    };
    let (_, errors, _) = engine::generate(&subject, &cmd, &[]);
    assert!(
        errors
            .iter()
            .any(|e| e.contains("simulate --dump") && e.contains("no role")),
        "{errors:#?}"
    );
    // And an output flag that no baseline writes is reported too.
    let cmd = herdfit::cli::Cli::command().mut_subcommand("simulate", |c| {
        c.arg(
            clap::Arg::new("dump")
                .long("dump")
                .value_parser(clap::value_parser!(herdfit::cli::paths::OutFile)),
        )
    });
    let subject = Subject {
        verbs: table::verbs(cmd.clone()),
        ..herdfit_subject()
    };
    let (_, errors, _) = engine::generate(&subject, &cmd, &[]);
    assert!(
        errors
            .iter()
            .any(|e| e.contains("simulate --dump") && e.contains("no baseline writes")),
        "{errors:#?}"
    );
}
