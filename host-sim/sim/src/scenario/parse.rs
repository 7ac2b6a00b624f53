//! Loading: the raw file form and [`Scenario::from_toml_str`].

use serde::Deserialize;
use toml_edit::ImDocument;

use super::events::RawEvent;
use super::locate::{
    Problem, Seg, backticked, describe, humanize, line_col, locate, path_at, table_with_span,
};
use super::spec::{EstimatorSpec, MeasureSpec, PlantSpec, SimSpec, TwinSpec};
use super::temperature::TemperatureSpec;
use super::{Scenario, ScenarioError, ScenarioErrorKind};

pub(super) fn default_seed() -> u64 {
    1
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScenario {
    name: String,
    #[serde(default)]
    description: String,
    duration_s: f64,
    #[serde(default = "default_seed")]
    seed: u64,
    #[serde(default)]
    plant: PlantSpec,
    #[serde(default)]
    sim: SimSpec,
    #[serde(default)]
    estimator: EstimatorSpec,
    #[serde(default)]
    twin: Option<TwinSpec>,
    #[serde(default)]
    event: Vec<RawEvent>,
    #[serde(default)]
    measure: Vec<MeasureSpec>,
    #[serde(default)]
    temperature: Option<TemperatureSpec>,
}

/// An error of `source` at the byte offset `pos` of `text` (its line and column).
fn error_at(
    text: &str,
    source: &str,
    kind: ScenarioErrorKind,
    pos: Option<usize>,
    context: Option<String>,
    message: String,
) -> ScenarioError {
    let (line, column) = match pos.map(|p| line_col(text, p)) {
        Some((l, c)) => (Some(l), Some(c)),
        None => (None, None),
    };
    ScenarioError {
        kind,
        file: source.to_string(),
        line,
        column,
        context,
        message,
    }
}

/// Turns positions and paths of one TOML text into [`ScenarioError`]s.
struct Locator<'a> {
    text: &'a str,
    source: &'a str,
    root: &'a toml_edit::Table,
}

impl Locator<'_> {
    fn err(
        &self,
        kind: ScenarioErrorKind,
        pos: Option<usize>,
        context: Option<String>,
        message: String,
    ) -> ScenarioError {
        error_at(self.text, self.source, kind, pos, context, message)
    }

    /// The string `key` of the `i`-th table of the array of tables `array`, if any.
    fn nth_str(&self, array: &str, i: usize, key: &str) -> Option<String> {
        self.root
            .get(array)
            .and_then(|e| e.as_array_of_tables())
            .and_then(|a| a.get(i))
            .and_then(|t| t.get(key))
            .and_then(|k| k.as_str())
            .map(str::to_string)
    }

    /// `field 'plant.wy2'`, `event #3 (kind "ramp"), field 'to'`, ...
    fn describe(&self, path: &[Seg]) -> Option<String> {
        describe(path, &|i| self.nth_str("event", i, "kind"), &|i| {
            self.nth_str("measure", i, "name")
        })
    }

    /// A semantic problem, at its path.
    fn located(&self, kind: ScenarioErrorKind, p: Problem) -> ScenarioError {
        self.err(
            kind,
            locate(self.root, &p.path),
            self.describe(&p.path),
            p.message,
        )
    }

    /// A serde/toml schema error: unknown or missing key, wrong type.
    fn schema(&self, e: &toml::de::Error) -> ScenarioError {
        let pos = e.span().map(|s| s.start);
        let mut at = Vec::new();
        if let Some(p) = pos {
            path_at(self.root, p, &mut at);
        }
        if let Some(missing) = e.message().strip_prefix("missing field ") {
            // The span is the table that lacks the key (0..0 for the root): point at its
            // header and name the key in the context.
            let name = backticked(missing)
                .first()
                .copied()
                .unwrap_or("?")
                .to_string();
            at.clear();
            if let Some(span) = e.span() {
                table_with_span(self.root, &span, &mut at);
            }
            let pos = locate(self.root, &at).filter(|_| !at.is_empty());
            at.push(Seg::Key(name));
            return self.err(
                ScenarioErrorKind::Schema,
                pos,
                self.describe(&at),
                "required key is missing".to_string(),
            );
        }
        // An unknown key: name it in the context.
        if let Some(bad) = e
            .message()
            .strip_prefix("unknown field ")
            .and_then(|r| backticked(r).first().map(|s| s.to_string()))
            && at.last() != Some(&Seg::Key(bad.clone()))
        {
            at.push(Seg::Key(bad));
        }
        self.err(
            ScenarioErrorKind::Schema,
            pos,
            self.describe(&at),
            humanize(e.message()),
        )
    }
}

impl Scenario {
    /// Parses and validates a scenario; `source` names the file in error messages and is kept
    /// in [`Scenario::source`].
    pub fn from_toml_str(text: &str, source: &str) -> Result<Scenario, ScenarioError> {
        let doc = ImDocument::parse(text).map_err(|e| {
            error_at(
                text,
                source,
                ScenarioErrorKind::Syntax,
                e.span().map(|s| s.start),
                None,
                format!("syntax error: {}", e.message().trim().replace('\n', "; ")),
            )
        })?;
        let at = Locator {
            text,
            source,
            root: doc.as_table(),
        };
        let raw: RawScenario = toml::from_str(text).map_err(|e| at.schema(&e))?;
        let mut events = Vec::with_capacity(raw.event.len());
        for (i, ev) in raw.event.iter().enumerate() {
            events.push(
                ev.convert(i)
                    .map_err(|p| at.located(ScenarioErrorKind::Schema, p))?,
            );
        }
        // Time order (stable); `order[k]` = file index of the k-th event in time.
        let mut order: Vec<usize> = (0..events.len()).collect();
        order.sort_by(|&a, &b| events[a].t_s.total_cmp(&events[b].t_s));
        let scenario = Scenario {
            name: raw.name,
            description: raw.description,
            duration_s: raw.duration_s,
            seed: raw.seed,
            plant: raw.plant,
            sim: raw.sim,
            estimator: raw.estimator,
            events: order.iter().map(|&i| events[i]).collect(),
            measures: raw.measure,
            twin: raw.twin,
            temperature: raw.temperature,
            source: source.to_string(),
        };
        scenario
            .check(&|k| order[k])
            .map_err(|p| at.located(ScenarioErrorKind::Invalid, p))?;
        Ok(scenario)
    }
}
