//! The errors of the scenario loader: `file:line:col: context: message`.

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

/// A scenario error naming the file, the line and column (where known) and the field,
/// displayed as `file:line:col: context: message`, e.g.
/// `scenarios/x.toml:12:7: field 'plant.wy2': expected a float, found a string "abc"`.
pub type ScenarioError = crate::located::LocatedError<ScenarioErrorKind>;
