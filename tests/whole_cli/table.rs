//! The command table, read from clap (issue #47): every verb (leaf subcommand) with each of its
//! arguments classified by the type its value parser produces — a path role
//! (`herdfit::cli::paths`), a number, a compound of numbers (`DX,DY`, `NXxNY`, …), or something
//! else (words, enums, switches). A new verb or flag appears here without anyone listing it.

use herdfit::cli::paths::*;
use std::any::TypeId;

/// What an argument's value is.
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    /// A path with its role.
    Path(Role),
    /// A floating-point number.
    Float,
    /// An integer (a count, a size, an index or a seed).
    Int,
    /// Several numbers in one value (`DX,DY`, `a..b`, `WxH`, `R,G,B`, `N@FRAME`); `float` when
    /// they are floating-point.
    Compound { float: bool },
    /// A plain `PathBuf`: a path with no role — an error of the command table.
    Unclassified,
    /// Anything else (a word, an enum, a switch).
    Other,
}

/// The role of a path argument.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    InFile,
    InDir,
    InPrefix,
    InFileOrWord,
    OutFile,
    OutTracks,
    OutDir,
    OutDirAll,
    OutFilesIn,
    StateDir,
}

impl Role {
    /// Whether the verb writes it.
    pub fn output(self) -> bool {
        matches!(
            self,
            Role::OutFile
                | Role::OutTracks
                | Role::OutDir
                | Role::OutDirAll
                | Role::OutFilesIn
                | Role::StateDir
        )
    }
    /// Whether it is a folder.
    pub fn folder(self) -> bool {
        matches!(
            self,
            Role::InDir | Role::OutDir | Role::OutDirAll | Role::OutFilesIn | Role::StateDir
        )
    }
}

/// One argument of a verb.
#[derive(Clone, Debug)]
pub struct Arg {
    /// clap's id.
    pub id: String,
    /// `--long`, or `None` for a positional.
    pub long: Option<String>,
    /// The value name (`TRACKS.csv`, `DX,DY`).
    pub value_name: String,
    pub value: Value,
    /// The default value clap fills in, if any.
    pub default: Option<String>,
    /// Takes several values (`Vec<…>`).
    pub many: bool,
    /// clap ids this argument cannot be used with.
    pub conflicts: Vec<String>,
    /// Takes a value (not a switch).
    pub takes_value: bool,
    /// A positional's place (1, 2, …); `None` for a flag.
    pub index: Option<usize>,
}

impl Arg {
    /// How the argument is named to the user.
    pub fn name(&self) -> String {
        match &self.long {
            Some(l) => format!("--{l}"),
            None => self.value_name.clone(),
        }
    }
}

/// One verb: its words (`["crowd", "simulate"]`) and arguments.
#[derive(Clone, Debug)]
pub struct Verb {
    pub words: Vec<String>,
    pub args: Vec<Arg>,
}

impl Verb {
    pub fn key(&self) -> String {
        self.words.join(" ")
    }
}

fn classify(a: &clap::Arg) -> Value {
    let t = a.get_value_parser().type_id();
    let roles: [(TypeId, Role); 10] = [
        (TypeId::of::<InFile>(), Role::InFile),
        (TypeId::of::<InDir>(), Role::InDir),
        (TypeId::of::<InPrefix>(), Role::InPrefix),
        (TypeId::of::<InFileOrWord>(), Role::InFileOrWord),
        (TypeId::of::<OutFile>(), Role::OutFile),
        (TypeId::of::<OutTracks>(), Role::OutTracks),
        (TypeId::of::<OutDir>(), Role::OutDir),
        (TypeId::of::<OutDirAll>(), Role::OutDirAll),
        (TypeId::of::<OutFilesIn>(), Role::OutFilesIn),
        (TypeId::of::<StateDir>(), Role::StateDir),
    ];
    if let Some((_, r)) = roles.iter().find(|(id, _)| t == *id) {
        return Value::Path(*r);
    }
    if !a.get_action().takes_values() || !a.get_possible_values().is_empty() {
        return Value::Other;
    }
    let is = |ids: &[TypeId]| ids.iter().any(|id| t == *id);
    if is(&[TypeId::of::<f64>(), TypeId::of::<f32>()]) {
        Value::Float
    } else if is(&[
        TypeId::of::<usize>(),
        TypeId::of::<u64>(),
        TypeId::of::<u32>(),
        TypeId::of::<u16>(),
        TypeId::of::<u8>(),
        TypeId::of::<i64>(),
        TypeId::of::<i32>(),
    ]) {
        Value::Int
    } else if is(&[TypeId::of::<(f64, f64)>(), TypeId::of::<[f64; 3]>()]) {
        Value::Compound { float: true }
    } else if is(&[
        TypeId::of::<(usize, usize)>(),
        TypeId::of::<(u32, u32)>(),
        TypeId::of::<[u8; 3]>(),
    ]) || format!("{t:?}").contains("UserCount")
    {
        Value::Compound { float: false }
    } else if is(&[
        TypeId::of::<std::path::PathBuf>(),
        TypeId::of::<std::ffi::OsString>(),
    ]) {
        Value::Unclassified
    } else {
        Value::Other
    }
}

fn walk(cmd: &clap::Command, words: Vec<String>, out: &mut Vec<Verb>) {
    let subs: Vec<&clap::Command> = cmd
        .get_subcommands()
        .filter(|c| c.get_name() != "help")
        .collect();
    if subs.is_empty() {
        let args = cmd
            .get_arguments()
            .filter(|a| a.get_id() != "help" && a.get_id() != "version")
            .map(|a| Arg {
                id: a.get_id().to_string(),
                long: a.get_long().map(str::to_string),
                value_name: a
                    .get_value_names()
                    .and_then(|v| v.first())
                    .map_or_else(|| a.get_id().to_string(), |v| v.to_string()),
                value: classify(a),
                default: a
                    .get_default_values()
                    .first()
                    .map(|v| v.to_string_lossy().into_owned()),
                many: a.get_num_args().is_some_and(|n| n.max_values() > 1)
                    || matches!(a.get_action(), clap::ArgAction::Append),
                conflicts: cmd
                    .get_arg_conflicts_with(a)
                    .iter()
                    .map(|c| c.get_id().to_string())
                    .collect(),
                takes_value: a.get_action().takes_values(),
                index: a.get_index(),
            })
            .collect();
        out.push(Verb { words, args });
        return;
    }
    for s in subs {
        let mut w = words.clone();
        w.push(s.get_name().to_string());
        walk(s, w, out);
    }
}

/// Every verb of `cmd` (built, so that flattened groups and conflicts are resolved).
pub fn verbs(cmd: clap::Command) -> Vec<Verb> {
    let mut cmd = cmd;
    cmd.build();
    let mut out = Vec::new();
    walk(&cmd, Vec::new(), &mut out);
    out
}
