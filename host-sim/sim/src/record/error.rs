//! The reader's errors: `file:line:col: context: message`.

use std::fmt;

/// What went wrong when reading a record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordErrorKind {
    /// The file could not be read (or is not UTF-8 text).
    Io,
    /// The file is empty.
    Empty,
    /// The `# format:` line is missing or names another format or version.
    Format,
    /// A required header key is missing, repeated or has a bad value.
    Header,
    /// The header row lacks a required column, repeats one, or is missing.
    Columns,
    /// A row has the wrong number of fields, or there are no rows.
    Row,
    /// A field is not a number.
    Number,
    /// `t_s` does not increase or is not sampled at fs_hz (±1 %).
    Time,
}

/// A record error naming the file, the line, the column (1-based field number, or the
/// character position on `#` lines) and the column or header key.
///
/// Displayed as `file:line:col: context: message`, e.g.
/// `file.csv:123:7: column 'x1_re_um': expected a number, found 'abc'`.
#[derive(Clone, Debug, PartialEq)]
pub struct RecordError {
    /// The kind of error.
    pub kind: RecordErrorKind,
    /// The file (the `source` given to the parser).
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<usize>,
    /// 1-based column: the field number on the header row and data rows, the character
    /// position of the value on `#` header lines.
    pub column: Option<usize>,
    /// The column or header key, e.g. `column 'x1_re_um'` or `header 'f0_hz'`.
    pub context: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.file)?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
            if let Some(col) = self.column {
                write!(f, ":{col}")?;
            }
        }
        f.write_str(": ")?;
        if let Some(ctx) = &self.context {
            write!(f, "{ctx}: ")?;
        }
        f.write_str(&self.message)
    }
}

impl std::error::Error for RecordError {}

/// A field as quoted in messages (at most 40 characters).
pub(super) fn quoted(s: &str) -> String {
    if s.is_empty() {
        return "an empty field".to_string();
    }
    let mut q: String = s.chars().take(40).collect();
    if q.len() < s.len() {
        q.push('…');
    }
    format!("'{q}'")
}
