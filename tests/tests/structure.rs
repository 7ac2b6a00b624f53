//! The house rules of the source tree (issue 9), checked on every test run so that they
//! hold after the next change too:
//!
//! * no non-test source file over 1000 lines, unless its first lines say why
//!   (`// size: <reason>`);
//! * no function body over 150 lines (a brace-counting scan of `fn` items; test files and
//!   `tests.rs` modules are exempt);
//! * no `#[path = ...]` includes;
//! * no JSON read back by key (`value["key"]`) in product or research code: results are
//!   typed structs with serde derive.

use std::fs;
use std::path::{Path, PathBuf};

const MAX_FILE_LINES: usize = 1000;
const MAX_FN_LINES: usize = 150;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// Every `.rs` file under the `src/` folders of every crate of the repository (the fuzz
/// crate's targets too; tests, benches, examples and build output excluded).
fn sources() -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack: Vec<PathBuf> = [
        "core/src",
        "firmware/src",
        "host-sim/sim/src",
        "host-sim/diagnose/src",
        "host-sim/papers/src",
        "host-sim/fw-replay/src",
        "host-sim/fil/src",
        "host-sim/cli/src",
        "host-sim/lot/src",
        "tests/src",
        "tests/xtask/src",
        "tests/fuzz/src",
        "tests/fuzz/fuzz_targets",
    ]
    .iter()
    .map(|d| root().join(d))
    .collect();
    while let Some(dir) = stack.pop() {
        let entries = fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
        for e in entries {
            let p = e.expect("dir entry").path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    assert!(out.len() > 50, "found only {} source files", out.len());
    out.sort();
    out
}

/// A test module in its own file (`tests.rs`, `props.rs` of a `#[cfg(test)] mod`).
fn is_test_file(p: &Path, text: &str) -> bool {
    let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
    name == "tests.rs" || name == "props.rs" || text.starts_with("//! Tests") || {
        // declared as `#[cfg(test)] mod NAME;` by its parent
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or("");
        let parent = p.parent().map(|d| d.with_extension("rs"));
        let mod_rs = p.parent().map(|d| d.join("mod.rs"));
        [parent, mod_rs].into_iter().flatten().any(|f| {
            fs::read_to_string(f).is_ok_and(|t| t.contains(&format!("#[cfg(test)]\nmod {stem};")))
        })
    }
}

fn rel(p: &Path) -> String {
    p.strip_prefix(root()).unwrap_or(p).display().to_string()
}

/// The code before the file's inline `#[cfg(test)]` module (the module itself is test code).
fn non_test_part(text: &str) -> &str {
    text.find("\n#[cfg(test)]\nmod tests {")
        .map_or(text, |i| &text[..i])
}

#[test]
fn no_source_file_over_1000_lines_without_a_reason() {
    let mut bad = Vec::new();
    for p in sources() {
        let text = fs::read_to_string(&p).expect("read");
        if is_test_file(&p, &text) {
            continue;
        }
        let n = non_test_part(&text).lines().count();
        let why = text.lines().take(30).any(|l| l.starts_with("// size: "));
        if n > MAX_FILE_LINES && !why {
            bad.push(format!("{}: {n} lines", rel(&p)));
        }
    }
    assert!(
        bad.is_empty(),
        "split these by concept (or say why in a `// size: ` line):\n{}",
        bad.join("\n")
    );
}

/// (name, first line, length) of every `fn` whose body is longer than `max` lines.
fn long_functions(text: &str, max: usize) -> Vec<(String, usize, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < lines.len() {
        let t = lines[i].trim_start();
        let is_fn = [
            "fn ",
            "pub fn ",
            "pub(crate) fn ",
            "pub(super) fn ",
            "const fn ",
            "pub const fn ",
        ]
        .iter()
        .any(|p| t.starts_with(p))
            || (t.starts_with("pub ") || t.starts_with("async ")) && t.contains(" fn ");
        if !is_fn || t.ends_with(';') {
            i += 1;
            continue;
        }
        let name = t
            .split("fn ")
            .nth(1)
            .and_then(|s| s.split(['(', '<']).next())
            .unwrap_or("?")
            .to_string();
        // find the opening brace, then its match (strings and chars with braces are rare
        // enough in this code base not to matter for a 150-line limit)
        let (mut depth, mut opened, mut j) = (0i64, false, i);
        'scan: while j < lines.len() {
            let code = lines[j].split("//").next().unwrap_or("");
            for c in code.chars() {
                match c {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => {
                        depth -= 1;
                        if opened && depth == 0 {
                            break 'scan;
                        }
                    }
                    ';' if !opened && depth == 0 => break 'scan, // a declaration
                    _ => {}
                }
            }
            j += 1;
        }
        let len = j.saturating_sub(i) + 1;
        if opened && len > max {
            out.push((name, i + 1, len));
        }
        i += 1;
    }
    out
}

#[test]
fn no_function_over_150_lines() {
    let mut bad = Vec::new();
    for p in sources() {
        let text = fs::read_to_string(&p).expect("read");
        if is_test_file(&p, &text) {
            continue;
        }
        for (name, line, len) in long_functions(non_test_part(&text), MAX_FN_LINES) {
            bad.push(format!("{}:{line}: fn {name}: {len} lines", rel(&p)));
        }
    }
    assert!(
        bad.is_empty(),
        "split these into their stages:\n{}",
        bad.join("\n")
    );
}

#[test]
fn the_function_scan_finds_a_long_function() {
    let body = "    x += 1;\n".repeat(MAX_FN_LINES + 5);
    let text = format!("fn short() {{\n}}\n\npub fn long(x: &mut u32) {{\n{body}}}\n");
    let found = long_functions(&text, MAX_FN_LINES);
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].0, "long");
    assert_eq!(found[0].1, 4);
}

#[test]
fn no_path_includes_and_no_json_read_by_key() {
    let mut bad = Vec::new();
    for p in sources() {
        let text = fs::read_to_string(&p).expect("read");
        let test_file = is_test_file(&p, &text);
        for (k, line) in non_test_part(&text).lines().enumerate() {
            let code = line.split("//").next().unwrap_or("");
            if code.contains("#[path") {
                bad.push(format!("{}:{}: #[path] include", rel(&p), k + 1));
            }
            // `v["key"]` on a serde_json::Value (array literals like `["a", "b"]` follow
            // `=`, `(`, `&` or a space, not an identifier or a closing bracket)
            let bytes: Vec<char> = code.chars().collect();
            for w in 1..bytes.len().saturating_sub(1) {
                if bytes[w] == '[' && bytes[w + 1] == '"' {
                    let prev = bytes[w - 1];
                    if !test_file
                        && (prev.is_alphanumeric() || prev == '_' || prev == ']' || prev == ')')
                    {
                        bad.push(format!(
                            "{}:{}: JSON read by key: {}",
                            rel(&p),
                            k + 1,
                            line.trim()
                        ));
                    }
                }
            }
        }
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
}
