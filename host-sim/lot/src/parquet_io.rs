//! The rows as a Parquet file: one column per [`columns`] entry (UTF-8 strings, `DOUBLE`,
//! `INT64`; every column but `record` and `path` optional, null where absent), one row
//! group, uncompressed (the crate is built without Parquet's codecs). pandas, pyarrow and
//! polars read it as plain columns.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::Path;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use parquet::basic::Compression;
use parquet::column::writer::ColumnWriter;
use parquet::data_type::ByteArray;
use parquet::file::properties::WriterProperties;
use parquet::file::reader::{FileReader, SerializedFileReader};
use parquet::file::writer::SerializedFileWriter;
use parquet::record::Field;
use parquet::schema::parser::parse_message_type;
use serde_json::{Map, Number, Value};

use crate::row::{Column, Kind, LotRow, columns};

/// The Parquet message type of the rows (the schema written in the file).
pub fn schema_text() -> String {
    let mut s = String::from("message paragyro_lot {\n");
    for c in columns() {
        let rep = if c.nullable { "OPTIONAL" } else { "REQUIRED" };
        let ty = match c.kind {
            Kind::Str => "BYTE_ARRAY",
            Kind::F64 => "DOUBLE",
            Kind::I64 => "INT64",
        };
        let ann = if c.kind == Kind::Str { " (STRING)" } else { "" };
        s.push_str(&format!("  {rep} {ty} {}{ann};\n", c.name));
    }
    s.push('}');
    s
}

/// A row as its flat JSON object (the serde keys are the columns' names).
fn flat(row: &LotRow) -> Result<Map<String, Value>> {
    match serde_json::to_value(row).context("cannot serialise a row")? {
        Value::Object(m) => Ok(m),
        _ => bail!("a row did not serialise to an object"),
    }
}

/// Writes `rows` to `path` (created or replaced).
pub fn write_parquet(path: &Path, rows: &[LotRow]) -> Result<()> {
    let cols = columns();
    let maps: Vec<Map<String, Value>> = rows.iter().map(flat).collect::<Result<_>>()?;
    let schema = Arc::new(parse_message_type(&schema_text()).context("the row schema")?);
    let props = Arc::new(
        WriterProperties::builder()
            .set_compression(Compression::UNCOMPRESSED)
            .set_created_by("paragyro-lot".into())
            .build(),
    );
    let file = File::create(path).with_context(|| format!("cannot create {}", path.display()))?;
    let mut w = SerializedFileWriter::new(file, schema, props)
        .with_context(|| format!("cannot write {}", path.display()))?;
    let mut rg = w.next_row_group()?;
    let mut i = 0;
    while let Some(mut col) = rg.next_column()? {
        let c = cols
            .get(i)
            .with_context(|| format!("the schema has more columns than the {}", cols.len()))?;
        write_column(col.untyped(), c, &maps)
            .with_context(|| format!("column {} of {}", c.name, path.display()))?;
        col.close()?;
        i += 1;
    }
    rg.close()?;
    w.close()
        .with_context(|| format!("cannot finish {}", path.display()))?;
    Ok(())
}

/// One column's values and definition levels (1 present, 0 null).
fn write_column(w: &mut ColumnWriter<'_>, c: &Column, maps: &[Map<String, Value>]) -> Result<()> {
    let cell = |m: &Map<String, Value>| m.get(&c.name).filter(|v| !v.is_null()).cloned();
    let defs: Vec<i16> = maps.iter().map(|m| i16::from(cell(m).is_some())).collect();
    let defs = c.nullable.then_some(defs.as_slice());
    let missing = |m: &Map<String, Value>| {
        format!(
            "{}: a value of the wrong type or missing",
            m.get("record").map_or("?".into(), Value::to_string)
        )
    };
    match (w, c.kind) {
        (ColumnWriter::ByteArrayColumnWriter(t), Kind::Str) => {
            let mut vals = Vec::new();
            for m in maps {
                match cell(m) {
                    Some(Value::String(s)) => vals.push(ByteArray::from(s.as_str())),
                    None if c.nullable => {}
                    _ => bail!(missing(m)),
                }
            }
            t.write_batch(&vals, defs, None)?;
        }
        (ColumnWriter::DoubleColumnWriter(t), Kind::F64) => {
            let mut vals = Vec::new();
            for m in maps {
                match cell(m) {
                    Some(Value::Number(n)) => vals.push(n.as_f64().context("not an f64")?),
                    None if c.nullable => {}
                    _ => bail!(missing(m)),
                }
            }
            t.write_batch(&vals, defs, None)?;
        }
        (ColumnWriter::Int64ColumnWriter(t), Kind::I64) => {
            let mut vals = Vec::new();
            for m in maps {
                match cell(m) {
                    Some(Value::Number(n)) => vals.push(n.as_i64().context("not an i64")?),
                    None if c.nullable => {}
                    _ => bail!(missing(m)),
                }
            }
            t.write_batch(&vals, defs, None)?;
        }
        _ => bail!("the writer's column type is not the schema's {:?}", c.kind),
    }
    Ok(())
}

/// Reads the rows of a Parquet file written by [`write_parquet`] (or any file with its
/// columns; columns it does not know are ignored, missing optional ones read as null).
pub fn read_parquet(path: &Path) -> Result<Vec<LotRow>> {
    let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
    let reader = SerializedFileReader::new(file)
        .with_context(|| format!("{} is not a Parquet file", path.display()))?;
    let known: BTreeMap<String, Kind> = columns().into_iter().map(|c| (c.name, c.kind)).collect();
    let mut rows = Vec::new();
    let iter = reader
        .get_row_iter(None)
        .with_context(|| format!("cannot read the rows of {}", path.display()))?;
    for (i, r) in iter.enumerate() {
        let r = r.with_context(|| format!("{}: row {i}", path.display()))?;
        let mut m = Map::new();
        for (name, field) in r.get_column_iter() {
            let Some(&kind) = known.get(name) else {
                continue;
            };
            // a null is an absent key: a missing `Option` reads as `None`, and the
            // flattened values hold only the columns present
            let v = match (field, kind) {
                (Field::Null, _) => continue,
                (Field::Str(s), Kind::Str) => Value::String(s.clone()),
                (Field::Double(x), Kind::F64) => {
                    Number::from_f64(*x).map_or(Value::Null, Value::Number)
                }
                (Field::Long(x), Kind::I64) => Value::Number((*x).into()),
                (f, k) => bail!(
                    "{}: row {i}, column {name}: {f:?} is not {k:?}",
                    path.display()
                ),
            };
            m.insert(name.clone(), v);
        }
        let row: LotRow = serde_json::from_value(Value::Object(m))
            .with_context(|| format!("{}: row {i} is not a lot row", path.display()))?;
        rows.push(row);
    }
    Ok(rows)
}
