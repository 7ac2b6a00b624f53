//! Loading: the raw file form and [`Scenario::from_toml_str`].

use serde::Deserialize;
use toml_edit::ImDocument;

use super::events::RawEvent;
use super::locate::{
    Problem, Seg, backticked, describe, humanize, line_col, locate, path_at, table_with_span,
};
use super::spec::{EstimatorSpec, MeasureSpec, PlantSpec, SimSpec, TwinSpec};
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
}

impl Scenario {
    /// Parses and validates a scenario; `source` names the file in error messages and is kept
    /// in [`Scenario::source`].
    pub fn from_toml_str(text: &str, source: &str) -> Result<Scenario, ScenarioError> {
        let err = |kind, pos: Option<usize>, context: Option<String>, message: String| {
            let (line, column) = match pos {
                Some(p) => {
                    let (l, c) = line_col(text, p);
                    (Some(l), Some(c))
                }
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
        };

        let doc = ImDocument::parse(text).map_err(|e| {
            err(
                ScenarioErrorKind::Syntax,
                e.span().map(|s| s.start),
                None,
                format!("syntax error: {}", e.message().trim().replace('\n', "; ")),
            )
        })?;
        let root = doc.as_table();
        let event_kind = |i: usize| {
            root.get("event")
                .and_then(|e| e.as_array_of_tables())
                .and_then(|a| a.get(i))
                .and_then(|t| t.get("kind"))
                .and_then(|k| k.as_str())
                .map(str::to_string)
        };
        let measure_name = |i: usize| {
            root.get("measure")
                .and_then(|e| e.as_array_of_tables())
                .and_then(|a| a.get(i))
                .and_then(|t| t.get("name"))
                .and_then(|k| k.as_str())
                .map(str::to_string)
        };
        let located = |kind, p: Problem| {
            err(
                kind,
                locate(root, &p.path),
                describe(&p.path, &event_kind, &measure_name),
                p.message,
            )
        };

        let raw: RawScenario = toml::from_str(text).map_err(|e| {
            let pos = e.span().map(|s| s.start);
            let mut at = Vec::new();
            if let Some(p) = pos {
                path_at(root, p, &mut at);
            }
            let message = humanize(e.message());
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
                    table_with_span(root, &span, &mut at);
                }
                let pos = locate(root, &at).filter(|_| !at.is_empty());
                at.push(Seg::Key(name));
                return err(
                    ScenarioErrorKind::Schema,
                    pos,
                    describe(&at, &event_kind, &measure_name),
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
            err(
                ScenarioErrorKind::Schema,
                pos,
                describe(&at, &event_kind, &measure_name),
                message,
            )
        })?;

        let mut events = Vec::with_capacity(raw.event.len());
        for (i, ev) in raw.event.iter().enumerate() {
            events.push(
                ev.convert(i)
                    .map_err(|p| located(ScenarioErrorKind::Schema, p))?,
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
            source: source.to_string(),
        };
        scenario
            .check(&|k| order[k])
            .map_err(|p| located(ScenarioErrorKind::Invalid, p))?;
        Ok(scenario)
    }
}
