//! The errors of the scenario loader: `file:line:col: context: message`.

use std::fmt;

/// What went wrong when loading a scenario.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScenarioErrorKind {
    /// The file could not be read.
    Io,
    /// The file is not valid TOML.
    Syntax,
    /// Unknown key, wrong type, missing key, unknown event kind or parameter.
    Schema,
    /// A value out of range or inconsistent.
    Invalid,
    /// Neither a built-in name nor an existing file.
    UnknownScenario,
}

/// A scenario error naming the file, the line and column (where known) and the field.
///
/// Displayed as `file:line:col: context: message`, e.g.
/// `scenarios/x.toml:12:7: field 'plant.wy2': expected a float, found a string "abc"`.
#[derive(Clone, Debug, PartialEq)]
pub struct ScenarioError {
    /// The kind of error.
    pub kind: ScenarioErrorKind,
    /// The file path, `"built-in"`, or empty when there is no file.
    pub file: String,
    /// 1-based line, where known.
    pub line: Option<usize>,
    /// 1-based column (in characters), where known.
    pub column: Option<usize>,
    /// The field or element, e.g. `field 'plant.wy2'` or `event #3 (kind "ramp"), field 'param'`.
    pub context: Option<String>,
    /// What is wrong.
    pub message: String,
}

impl fmt::Display for ScenarioError {
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

impl std::error::Error for ScenarioError {}
