//! Every intra-repository link in every markdown file of the repository resolves: a relative
//! link names a file or folder that exists, and its `#anchor` (or a bare `#anchor` in the
//! same file) names a heading of the target, slugged as GitHub does. Links to the web
//! (`http://`, `https://`, `mailto:`) are not checked; links inside code (fenced blocks and
//! inline code spans) are not links.

use std::collections::HashSet;
use std::fs;
use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("workspace root")
        .to_path_buf()
}

/// Every `.md` file of the repository (build output, git and fuzzing corpora excluded).
fn markdown_files() -> Vec<PathBuf> {
    let skip = ["target", ".git", "corpus", "artifacts"];
    let mut out = Vec::new();
    let mut stack = vec![root()];
    while let Some(dir) = stack.pop() {
        for e in fs::read_dir(&dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
            let p = e.expect("dir entry").path();
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if p.is_dir() {
                if !skip.contains(&name) {
                    stack.push(p);
                }
            } else if name.ends_with(".md") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The text outside fenced code blocks, line by line (fenced lines blanked).
fn prose_lines(text: &str) -> Vec<String> {
    let mut fenced = false;
    text.lines()
        .map(|l| {
            if l.trim_start().starts_with("```") {
                fenced = !fenced;
                return String::new();
            }
            if fenced { String::new() } else { l.to_string() }
        })
        .collect()
}

/// A line with its inline code spans removed.
fn without_code_spans(line: &str) -> String {
    let mut out = String::new();
    let mut in_code = false;
    for c in line.chars() {
        if c == '`' {
            in_code = !in_code;
        } else if !in_code {
            out.push(c);
        }
    }
    out
}

/// GitHub's anchor of a heading: lower case, punctuation dropped (letters, digits, `-`, `_`
/// and spaces kept), spaces to `-`.
fn slug(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == '-' || *c == '_' || *c == ' ')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The anchors of a markdown file's headings (duplicates numbered `-1`, `-2`, … as GitHub
/// does).
fn anchors(text: &str) -> HashSet<String> {
    let mut out = HashSet::new();
    for l in prose_lines(text) {
        let t = l.trim_start();
        if !t.starts_with('#') {
            continue;
        }
        let title = t.trim_start_matches('#');
        if !title.starts_with(' ') {
            continue;
        }
        let base = slug(&title.replace('`', ""));
        let mut s = base.clone();
        let mut k = 0;
        while out.contains(&s) {
            k += 1;
            s = format!("{base}-{k}");
        }
        out.insert(s);
    }
    out
}

/// The targets of the inline links `[text](target)` of a line.
fn link_targets(line: &str) -> Vec<String> {
    let mut out = Vec::new();
    let b: Vec<char> = line.chars().collect();
    let mut i = 0;
    while i + 1 < b.len() {
        if b[i] == ']' && b[i + 1] == '(' {
            let mut depth = 1;
            let mut j = i + 2;
            while j < b.len() && depth > 0 {
                match b[j] {
                    '(' => depth += 1,
                    ')' => depth -= 1,
                    _ => {}
                }
                j += 1;
            }
            if depth == 0 {
                let t: String = b[i + 2..j - 1].iter().collect();
                // `[text](target "title")`
                let t = t.split_whitespace().next().unwrap_or("").to_string();
                out.push(t);
            }
            i = j;
        } else {
            i += 1;
        }
    }
    out
}

/// The broken links of one file: `file:line: target (why)`.
fn broken_links(file: &Path) -> Vec<String> {
    let text = fs::read_to_string(file).expect("read");
    let rel = file
        .strip_prefix(root())
        .unwrap_or(file)
        .display()
        .to_string();
    let mut bad = Vec::new();
    for (k, line) in prose_lines(&text).iter().enumerate() {
        for t in link_targets(&without_code_spans(line)) {
            if t.is_empty()
                || t.starts_with("http://")
                || t.starts_with("https://")
                || t.starts_with("mailto:")
            {
                continue;
            }
            let (path, anchor) = match t.split_once('#') {
                Some((p, a)) => (p, Some(a)),
                None => (t.as_str(), None),
            };
            let target = if path.is_empty() {
                file.to_path_buf()
            } else if path.starts_with('/') {
                bad.push(format!("{rel}:{}: {t} (absolute path)", k + 1));
                continue;
            } else {
                file.parent().expect("parent").join(path)
            };
            if !target.exists() {
                bad.push(format!("{rel}:{}: {t} (no such file)", k + 1));
                continue;
            }
            let Some(anchor) = anchor else { continue };
            if target.extension().is_some_and(|x| x == "md") {
                let other = fs::read_to_string(&target).expect("read");
                if !anchors(&other).contains(anchor) {
                    bad.push(format!("{rel}:{}: {t} (no such heading)", k + 1));
                }
            }
        }
    }
    bad
}

#[test]
fn every_intra_repo_link_in_the_markdown_resolves() {
    let files = markdown_files();
    assert!(
        files.iter().any(|f| f.ends_with("README.md")),
        "found no README.md under {}",
        root().display()
    );
    let bad: Vec<String> = files.iter().flat_map(|f| broken_links(f)).collect();
    assert!(bad.is_empty(), "broken links:\n{}", bad.join("\n"));
}

#[test]
fn the_checker_finds_a_broken_link_and_a_missing_heading() {
    let dir = std::env::temp_dir().join(format!("paragyro-links-{}", std::process::id()));
    fs::create_dir_all(&dir).expect("mkdir");
    let a = dir.join("a.md");
    fs::write(dir.join("b.md"), "# Title\n\n## The `x` part (measured)\n").expect("write");
    fs::write(
        &a,
        "# A\n\n[ok](b.md), [ok](b.md#the-x-part-measured), [ok](#a), [web](https://x.y/z)\n\
         `[code](nowhere.md)`\n```\n[fenced](nowhere.md)\n```\n\
         [bad](c.md) [bad](b.md#nope) [bad](#nope)\n",
    )
    .expect("write");
    let bad = broken_links(&a);
    fs::remove_dir_all(&dir).ok();
    assert_eq!(bad.len(), 3, "{bad:?}");
    assert!(bad[0].contains("c.md (no such file)"), "{bad:?}");
    assert!(bad[1].contains("b.md#nope (no such heading)"), "{bad:?}");
    assert!(bad[2].contains("#nope (no such heading)"), "{bad:?}");
}

#[test]
fn slugs_are_githubs() {
    assert_eq!(
        slug("Limits (measured, not hidden)"),
        "limits-measured-not-hidden"
    );
    assert_eq!(
        slug("Warm start on the stm32f405 board (feature warm-start)"),
        "warm-start-on-the-stm32f405-board-feature-warm-start"
    );
    assert_eq!(
        slug("7. The paper's errata, in one list"),
        "7-the-papers-errata-in-one-list"
    );
    assert_eq!(
        slug("Capture: a real device's run as a record"),
        "capture-a-real-devices-run-as-a-record"
    );
}
