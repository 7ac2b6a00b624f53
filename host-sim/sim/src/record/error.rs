//! The reader's errors: `file:line:col: context: message`.

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
/// character position on `#` lines) and the column or header key, displayed as
/// `file:line:col: context: message`, e.g.
/// `file.csv:123:7: column 'x1_re_um': expected a number, found 'abc'`.
pub type RecordError = crate::located::LocatedError<RecordErrorKind>;

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
