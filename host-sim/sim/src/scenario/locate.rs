//! Locating a problem in the TOML text: paths into the document, their byte offsets and
//! line/column, and the wording of serde/toml messages.

use toml_edit::{Item, TableLike, Value};

/// One step of a path into the TOML document.
#[derive(Clone, Debug, PartialEq)]
pub(super) enum Seg {
    Key(String),
    Index(usize),
}

pub(super) fn key(k: &str) -> Seg {
    Seg::Key(k.to_string())
}

pub(super) fn path(keys: &[&str]) -> Vec<Seg> {
    keys.iter().map(|k| key(k)).collect()
}

/// A semantic problem, located by its path in the document.
#[derive(Clone, Debug)]
pub(super) struct Problem {
    pub(super) path: Vec<Seg>,
    pub(super) message: String,
}

pub(super) fn problem(path: Vec<Seg>, message: impl Into<String>) -> Problem {
    Problem {
        path,
        message: message.into(),
    }
}

/// Human description of a path: `field 'plant.wy2'`, `event #3 (kind "ramp"), field 'to'`.
pub(super) fn describe(
    path: &[Seg],
    event_kind: &dyn Fn(usize) -> Option<String>,
    measure_name: &dyn Fn(usize) -> Option<String>,
) -> Option<String> {
    fn dotted(segs: &[Seg]) -> String {
        let mut s = String::new();
        for seg in segs {
            match seg {
                Seg::Key(k) => {
                    if !s.is_empty() {
                        s.push('.');
                    }
                    s.push_str(k);
                }
                Seg::Index(i) => s.push_str(&format!("[{i}]")),
            }
        }
        s
    }
    match path {
        [] => None,
        [Seg::Key(k), Seg::Index(i), rest @ ..] if k == "event" || k == "measure" => {
            let mut s = if k == "event" {
                match event_kind(*i) {
                    Some(kind) => format!("event #{} (kind \"{kind}\")", i + 1),
                    None => format!("event #{}", i + 1),
                }
            } else {
                match measure_name(*i) {
                    Some(name) => format!("measure #{} (\"{name}\")", i + 1),
                    None => format!("measure #{}", i + 1),
                }
            };
            if !rest.is_empty() {
                s.push_str(&format!(", field '{}'", dotted(rest)));
            }
            Some(s)
        }
        _ => Some(format!("field '{}'", dotted(path))),
    }
}

/// 1-based (line, column) of a byte offset.
pub(super) fn line_col(text: &str, pos: usize) -> (usize, usize) {
    let pos = pos.min(text.len());
    let mut pos = pos;
    while !text.is_char_boundary(pos) {
        pos -= 1;
    }
    let before = &text[..pos];
    let line = before.matches('\n').count() + 1;
    let line_start = before.rfind('\n').map_or(0, |i| i + 1);
    (line, before[line_start..].chars().count() + 1)
}

/// Deepest element of `path` present in the document: its byte offset (the key when there is one).
pub(super) fn locate(doc: &toml_edit::Table, path: &[Seg]) -> Option<usize> {
    enum Node<'a> {
        Table(&'a dyn TableLike),
        Tables(&'a toml_edit::ArrayOfTables),
        Array(&'a toml_edit::Array),
        Leaf,
    }
    fn node_of_value(v: &Value) -> Node<'_> {
        match v {
            Value::InlineTable(t) => Node::Table(t),
            Value::Array(a) => Node::Array(a),
            _ => Node::Leaf,
        }
    }
    fn node_of(item: &Item) -> Node<'_> {
        match item {
            Item::Table(t) => Node::Table(t),
            Item::ArrayOfTables(a) => Node::Tables(a),
            Item::Value(v) => node_of_value(v),
            Item::None => Node::Leaf,
        }
    }
    let mut best = doc.span().map(|s| s.start);
    let mut node = Node::Table(doc);
    for seg in path {
        node = match (seg, node) {
            (Seg::Key(k), Node::Table(t)) => match t.get_key_value(k) {
                Some((key, item)) => {
                    best = key.span().or_else(|| item.span()).map(|s| s.start).or(best);
                    node_of(item)
                }
                None => break,
            },
            (Seg::Index(i), Node::Tables(a)) => match a.get(*i) {
                Some(t) => {
                    best = t.span().map(|s| s.start).or(best);
                    Node::Table(t)
                }
                None => break,
            },
            (Seg::Index(i), Node::Array(a)) => match a.get(*i) {
                Some(v) => {
                    best = v.span().map(|s| s.start).or(best);
                    node_of_value(v)
                }
                None => break,
            },
            _ => break,
        };
    }
    best
}

/// The path of the deepest key/value of the document containing byte offset `pos`.
pub(super) fn path_at(table: &dyn TableLike, pos: usize, out: &mut Vec<Seg>) -> bool {
    let within = |span: Option<std::ops::Range<usize>>| span.is_some_and(|s| s.contains(&pos));
    for (k, item) in table.iter() {
        let key_span = table.key(k).and_then(|key| key.span());
        let whole = match (key_span.clone(), item.span()) {
            (Some(a), Some(b)) => Some(a.start.min(b.start)..a.end.max(b.end)),
            (a, b) => a.or(b),
        };
        match item {
            Item::Table(t) => {
                out.push(key(k));
                if path_at(t, pos, out) || within(t.span()) || within(key_span) {
                    return true;
                }
                out.pop();
            }
            Item::ArrayOfTables(a) => {
                for (i, t) in a.iter().enumerate() {
                    out.push(key(k));
                    out.push(Seg::Index(i));
                    if path_at(t, pos, out) || within(t.span()) {
                        return true;
                    }
                    out.pop();
                    out.pop();
                }
            }
            Item::Value(v) => {
                if within(whole.clone()) {
                    out.push(key(k));
                    match v {
                        Value::InlineTable(t) => {
                            path_at(t, pos, out);
                        }
                        Value::Array(a) => {
                            if let Some((i, v)) =
                                a.iter().enumerate().find(|(_, v)| within(v.span()))
                            {
                                out.push(Seg::Index(i));
                                if let Value::InlineTable(t) = v {
                                    path_at(t, pos, out);
                                }
                            }
                        }
                        _ => {}
                    }
                    return true;
                }
            }
            Item::None => {}
        }
    }
    false
}

/// A sub-table of a TOML table: (index in an array of tables, the table, its span).
pub(super) type SubTable<'a> = (
    Option<usize>,
    &'a dyn TableLike,
    Option<std::ops::Range<usize>>,
);

/// The path of the (sub)table whose span is exactly `span`.
pub(super) fn table_with_span(
    table: &dyn TableLike,
    span: &std::ops::Range<usize>,
    out: &mut Vec<Seg>,
) -> bool {
    for (k, item) in table.iter() {
        let subtables: Vec<SubTable<'_>> = match item {
            Item::Table(t) => vec![(None, t as &dyn TableLike, t.span())],
            Item::ArrayOfTables(a) => a
                .iter()
                .enumerate()
                .map(|(i, t)| (Some(i), t as &dyn TableLike, t.span()))
                .collect(),
            Item::Value(Value::InlineTable(t)) => vec![(None, t as &dyn TableLike, t.span())],
            _ => Vec::new(),
        };
        for (index, t, t_span) in subtables {
            out.push(key(k));
            if let Some(i) = index {
                out.push(Seg::Index(i));
            }
            if t_span.as_ref() == Some(span) || table_with_span(t, span, out) {
                return true;
            }
            out.pop();
            if index.is_some() {
                out.pop();
            }
        }
    }
    false
}

/// Text between backticks: "unknown field `a`, expected `b` or `c`" → ["a", "b", "c"].
pub(super) fn backticked(msg: &str) -> Vec<&str> {
    msg.split('`').skip(1).step_by(2).collect()
}

/// Rewrites serde/toml messages into the wording of this module.
pub(super) fn humanize(msg: &str) -> String {
    let msg = msg.trim();
    if let Some(rest) = msg.strip_prefix("unknown field ") {
        let names = backticked(rest);
        let (bad, expected) = names.split_first().unwrap_or((&"?", &[]));
        return if expected.is_empty() {
            format!("unknown key '{bad}' (this table takes no keys)")
        } else {
            format!(
                "unknown key '{bad}' (expected one of: {})",
                expected.join(", ")
            )
        };
    }
    if let Some(rest) = msg.strip_prefix("unknown variant ") {
        let names = backticked(rest);
        let (bad, expected) = names.split_first().unwrap_or((&"?", &[]));
        return format!(
            "unknown value '{bad}' (expected one of: {})",
            expected.join(", ")
        );
    }
    if let Some(rest) = msg.strip_prefix("missing field ") {
        let names = backticked(rest);
        return format!(
            "required key '{}' is missing",
            names.first().copied().unwrap_or("?")
        );
    }
    if let Some(rest) = msg.strip_prefix("invalid type: ")
        && let Some((found, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "expected {}, found {}",
            expected_name(expected),
            found_name(found)
        );
    }
    if let Some(rest) = msg.strip_prefix("invalid value: ")
        && let Some((found, expected)) = rest.split_once(", expected ")
    {
        return format!(
            "expected {}, found {}",
            expected_name(expected),
            found_name(found)
        );
    }
    msg.replace('\n', "; ")
}

pub(super) fn expected_name(e: &str) -> String {
    match e.trim() {
        "f64" | "f32" => "a float".into(),
        "usize" | "u64" | "u32" | "u16" | "u8" => "a non-negative integer".into(),
        "i64" | "i32" => "an integer".into(),
        "a boolean" | "bool" => "a boolean (true or false)".into(),
        "a string" => "a string".into(),
        "a sequence" => "an array (of tables: [[...]])".into(),
        other => other.into(),
    }
}

pub(super) fn found_name(f: &str) -> String {
    let f = f.trim();
    let value = |prefix: &str| f.strip_prefix(prefix).map(|v| v.trim().trim_matches('`'));
    if let Some(v) = value("string") {
        format!("a string ({v})")
    } else if let Some(v) = value("floating point") {
        format!("a float ({v})")
    } else if let Some(v) = value("integer") {
        format!("an integer ({v})")
    } else if let Some(v) = value("boolean") {
        format!("a boolean ({v})")
    } else if f == "map" {
        "a table".into()
    } else if f == "sequence" {
        "an array".into()
    } else {
        f.into()
    }
}
