//! The role of every path on the command line (issue #47). A path flag's type says what the verb
//! does with it — [`InFile`], [`InDir`], [`InPrefix`], [`InFileOrWord`] are read; [`OutFile`],
//! [`OutTracks`], [`OutDir`], [`OutDirAll`], [`OutFilesIn`], [`StateDir`] are written — so the dispatch derives
//! the run's output plan ([`plan_of`]) from the parsed command line itself, before the verb runs: a
//! verb cannot forget to declare a flag's file, and the whole-CLI test reads the same roles from
//! clap's command table. A plain `PathBuf` flag has no role and fails that test.
//!
//! Every role derefs to [`Path`], so a verb passes `&a.out` where a `&Path` is wanted.

use crate::data::atomic::plan::{Kind, Plan};
use clap::ArgMatches;
use std::ffi::OsString;
use std::path::{Path, PathBuf};

macro_rules! role {
    ($(#[$doc:meta])* $name:ident) => {
        $(#[$doc])*
        #[derive(Clone, Debug, PartialEq, Eq)]
        pub struct $name(pub PathBuf);

        impl From<OsString> for $name {
            fn from(s: OsString) -> Self {
                $name(PathBuf::from(s))
            }
        }
        impl From<&str> for $name {
            fn from(s: &str) -> Self {
                $name(PathBuf::from(s))
            }
        }
        impl std::ops::Deref for $name {
            type Target = Path;
            fn deref(&self) -> &Path {
                &self.0
            }
        }
        impl AsRef<Path> for $name {
            fn as_ref(&self) -> &Path {
                &self.0
            }
        }
        impl From<$name> for PathBuf {
            fn from(p: $name) -> PathBuf {
                p.0
            }
        }
        impl $name {
            /// The path as given.
            pub fn path(&self) -> PathBuf {
                self.0.clone()
            }
            /// The path as text (a keyword such as `auto`, or the file name).
            pub fn text(&self) -> std::borrow::Cow<'_, str> {
                self.0.to_string_lossy()
            }
        }
    };
}

role!(
    /// A file the verb reads (a tracks CSV's sidecar with it).
    InFile
);
role!(
    /// A folder the verb reads (a clip).
    InDir
);
role!(
    /// A prefix naming the three files of the public extractor (`PREFIX_data_meta.txt`, …).
    InPrefix
);
role!(
    /// A keyword (`auto`, `open`, …) or a file the verb reads: an input when it names a file.
    InFileOrWord
);
role!(
    /// A file the verb writes (`-`: standard output, where the verb streams).
    OutFile
);
role!(
    /// A tracks CSV the verb writes, with its JSON sidecar.
    OutTracks
);
role!(
    /// A folder the verb writes whole (its parent must exist).
    OutDir
);
role!(
    /// A folder the verb writes whole, missing parent folders created.
    OutDirAll
);
role!(
    /// A folder the verb writes files into (created if missing; the other files in it kept).
    OutFilesIn
);
role!(
    /// A folder the verb keeps its state in as it runs (checkpoints), read back to resume.
    StateDir
);

/// The suffixes of the three files behind an [`InPrefix`].
pub const PREFIX_FILES: [&str; 3] = ["_data_meta.txt", "_data_frame.txt", "_data_cell.txt"];

/// How an argument's role is read from parsed matches: its type and what it adds to a plan.
type Reader = fn(&ArgMatches, &str, &str, &mut Plan) -> bool;

fn read<T: Clone + Send + Sync + 'static + AsRef<Path>>(
    m: &ArgMatches,
    id: &str,
) -> Option<Vec<T>> {
    match m.try_get_many::<T>(id) {
        Ok(Some(v)) => Some(v.cloned().collect()),
        _ => None,
    }
}

macro_rules! reader {
    ($t:ty, |$p:ident, $what:ident, $plan:ident| $body:expr) => {
        (|m: &ArgMatches, id: &str, $what: &str, $plan: &mut Plan| match read::<$t>(m, id) {
            Some(v) => {
                for $p in v {
                    $body;
                }
                true
            }
            None => false,
        }) as Reader
    };
}

/// Every role and what it declares.
fn readers() -> [Reader; 10] {
    [
        reader!(InFile, |p, what, plan| plan.input(&p, what)),
        reader!(InDir, |p, what, plan| plan.input(&p, what)),
        reader!(InPrefix, |p, what, plan| for s in PREFIX_FILES {
            let mut f = p.0.clone().into_os_string();
            f.push(s);
            plan.input(Path::new(&f), what)
        }),
        reader!(InFileOrWord, |p, what, plan| if p.is_file() {
            plan.input(&p, what)
        }),
        reader!(OutFile, |p, what, plan| plan.output(&p, what, Kind::File)),
        reader!(OutTracks, |p, what, plan| plan.tracks_output(&p, what)),
        reader!(OutDir, |p, what, plan| plan.output(&p, what, Kind::Dir)),
        reader!(OutDirAll, |p, what, plan| plan.output(
            &p,
            what,
            Kind::DirAll
        )),
        reader!(OutFilesIn, |p, what, plan| plan.output(
            &p,
            what,
            Kind::Files
        )),
        reader!(StateDir, |p, what, plan| plan.output(&p, what, Kind::State)),
    ]
}

/// How an argument is named to the user: `--long`, or its value name for a positional.
pub fn arg_name(a: &clap::Arg) -> String {
    match a.get_long() {
        Some(l) => format!("--{l}"),
        None => a
            .get_value_names()
            .and_then(|v| v.first())
            .map_or_else(|| a.get_id().to_string(), |v| v.to_string()),
    }
}

/// The leaf command of `m` (the verb that runs) and its matches.
pub fn leaf<'a>(cmd: &'a clap::Command, m: &'a ArgMatches) -> (&'a clap::Command, &'a ArgMatches) {
    match m.subcommand() {
        Some((name, sub)) => match cmd.find_subcommand(name) {
            Some(c) => leaf(c, sub),
            None => (cmd, m),
        },
        None => (cmd, m),
    }
}

/// The run's output plan: every path argument of the verb by its role.
pub fn plan_of(cmd: &clap::Command, m: &ArgMatches) -> Plan {
    let (cmd, m) = leaf(cmd, m);
    let mut plan = Plan::new();
    let readers = readers();
    // Inputs first, so that every output is judged against all of them.
    for pass in [0..4, 4..10] {
        for a in cmd.get_arguments() {
            let id = a.get_id().as_str();
            let what = arg_name(a);
            for r in &readers[pass.clone()] {
                if r(m, id, &what, &mut plan) {
                    break;
                }
            }
        }
    }
    plan
}
