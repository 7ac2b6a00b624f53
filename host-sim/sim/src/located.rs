//! The error of a text input (a scenario TOML, a record CSV) that names where it is:
//! displayed as `file:line:col: context: message`, e.g.
//! `scenarios/x.toml:12:7: field 'plant.wy2': expected a float, found a string "abc"` or
//! `file.csv:123:7: column 'x1_re_um': expected a number, found 'abc'`. One type for both
//! formats ([`crate::scenario::ScenarioError`], [`crate::record::RecordError`]), generic over
//! the kind of error.

use std::fmt;

/// An error at a place in a file, of kind `K`.
#[derive(Clone, Debug, PartialEq)]
pub struct LocatedError<K> {
    /// The kind of error.
    pub kind: K,
    /// The file (the `source` given to the parser), `"built-in"`, or empty when there is no
    /// file (then the message has no location prefix).
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<usize>,
    /// 1-based column, where known (characters, or the field number of a CSV row).
    pub column: Option<usize>,
    /// The field, column or element, e.g. `field 'plant.wy2'` or `column 'x1_re_um'`.
    pub context: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl<K> fmt::Display for LocatedError<K> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if !self.file.is_empty() {
            f.write_str(&self.file)?;
            if let Some(line) = self.line {
                write!(f, ":{line}")?;
                if let Some(col) = self.column {
                    write!(f, ":{col}")?;
                }
            }
            f.write_str(": ")?;
        }
        if let Some(ctx) = &self.context {
            write!(f, "{ctx}: ")?;
        }
        f.write_str(&self.message)
    }
}

impl<K: fmt::Debug> std::error::Error for LocatedError<K> {}

#[cfg(test)]
mod tests {
    use super::LocatedError;

    fn err(file: &str, line: Option<usize>, column: Option<usize>) -> LocatedError<()> {
        LocatedError {
            kind: (),
            file: file.into(),
            line,
            column,
            context: Some("field 'plant.wy2'".into()),
            message: "expected a float".into(),
        }
    }

    #[test]
    fn displays_file_line_col_context_message() {
        assert_eq!(
            err("x.toml", Some(12), Some(7)).to_string(),
            "x.toml:12:7: field 'plant.wy2': expected a float"
        );
        assert_eq!(
            err("x.toml", Some(12), None).to_string(),
            "x.toml:12: field 'plant.wy2': expected a float"
        );
        assert_eq!(
            err("x.toml", None, Some(7)).to_string(),
            "x.toml: field 'plant.wy2': expected a float"
        );
        assert_eq!(
            err("", Some(3), Some(1)).to_string(),
            "field 'plant.wy2': expected a float"
        );
    }
}
