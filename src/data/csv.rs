//! The CSV lines of herdfit's formats (tracks, initial herds): comma-separated fields, trimmed,
//! read by column with errors that name the file, the line and the column.

use crate::error::{Error, Result};
use std::path::Path;

/// One data line of a CSV file.
pub struct Record<'a> {
    path: &'a Path,
    /// 1-based line number in the file.
    line: usize,
    fields: Vec<&'a str>,
}

impl<'a> Record<'a> {
    /// Line `line` (1-based) of `path`, holding `text`.
    pub fn new(path: &'a Path, line: usize, text: &'a str) -> Self {
        Record {
            path,
            line,
            fields: text.split(',').map(str::trim).collect(),
        }
    }

    /// The 1-based line number.
    pub fn line(&self) -> usize {
        self.line
    }

    /// The field of column `col` (named `name` in errors).
    pub fn get(&self, col: usize, name: &str) -> Result<&'a str> {
        self.fields.get(col).copied().ok_or_else(|| {
            Error::file(
                self.path,
                format!("line {}: missing column '{name}'", self.line),
            )
        })
    }

    /// Column `col` as a finite number.
    pub fn num(&self, col: usize, name: &str) -> Result<f64> {
        let s = self.get(col, name)?;
        let v: f64 = s.parse().map_err(|_| {
            Error::file(
                self.path,
                format!("line {}: {name} = '{s}' is not a number", self.line),
            )
        })?;
        if !v.is_finite() {
            return Err(Error::file(
                self.path,
                format!("line {}: {name} is {v}", self.line),
            ));
        }
        Ok(v)
    }

    /// Column `col` as a finite number, or `None` for a missing value (`NaN` or an empty
    /// field, as trackers write an animal they lost); infinities and other text are errors.
    pub fn num_or_missing(&self, col: usize, name: &str) -> Result<Option<f64>> {
        let s = self.get(col, name)?;
        if s.is_empty() || s.eq_ignore_ascii_case("nan") {
            return Ok(None);
        }
        self.num(col, name).map(Some)
    }

    /// Column `col` as a non-negative integer.
    pub fn int(&self, col: usize, name: &str) -> Result<u64> {
        let s = self.get(col, name)?;
        s.parse().map_err(|_| {
            Error::file(
                self.path,
                format!(
                    "line {}: {name} = '{s}' is not a non-negative integer",
                    self.line
                ),
            )
        })
    }
}

/// A CSV text with a header line: its columns, and its non-blank data lines as [`Record`]s.
pub struct Table<'a> {
    path: &'a Path,
    columns: Vec<&'a str>,
    lines: Vec<(usize, &'a str)>,
}

impl<'a> Table<'a> {
    /// The table in `text`, read from `path`; `expected` describes the header for the error of
    /// an empty file.
    pub fn parse(path: &'a Path, text: &'a str, expected: &str) -> Result<Self> {
        let mut lines = text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty());
        let Some((_, header)) = lines.next() else {
            return Err(Error::file(
                path,
                format!("empty file (expected header {expected})"),
            ));
        };
        Ok(Table {
            path,
            columns: header.split(',').map(str::trim).collect(),
            lines: lines.map(|(k, l)| (k + 1, l)).collect(),
        })
    }

    /// The column named `name`, if the header has it.
    pub fn find(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| *c == name)
    }

    /// The column named `name`, which the header must have.
    pub fn need(&self, name: &str) -> Result<usize> {
        self.find(name)
            .ok_or_else(|| Error::file(self.path, format!("header lacks column '{name}'")))
    }

    /// The data lines.
    pub fn records(&self) -> impl Iterator<Item = Record<'a>> + '_ {
        self.lines
            .iter()
            .map(|&(line, text)| Record::new(self.path, line, text))
    }
}

/// The numbers of one text row (`fields`, named `names`; line `ln`, 0-based): each finite, and the
/// first two (`frame`, `id`) non-negative integers. Errors name the file, line and field.
pub fn frame_id_row<const N: usize>(
    path: &Path,
    ln: usize,
    fields: &[&str],
    names: [&str; N],
) -> Result<[f64; N]> {
    let mut v = [0.0f64; N];
    for (k, name) in names.iter().enumerate() {
        v[k] = fields[k].parse().map_err(|_| {
            Error::file(
                path,
                format!("line {}: {name} = '{}' is not a number", ln + 1, fields[k]),
            )
        })?;
        if !v[k].is_finite() {
            return Err(Error::file(
                path,
                format!("line {}: {name} is {}", ln + 1, v[k]),
            ));
        }
    }
    for k in 0..N.min(2) {
        if v[k] < 0.0 || v[k].fract() != 0.0 || v[k] > 1e15 {
            return Err(Error::file(
                path,
                format!(
                    "line {}: {} = {} is not a non-negative integer",
                    ln + 1,
                    names[k],
                    v[k]
                ),
            ));
        }
    }
    Ok(v)
}
