//! ARCHITECTURE.md stays a true map: every path written in backticks exists
//! and every name written in backticks still occurs in the workspace's
//! sources (Rust, Cargo manifests, proto files), and the map stays within
//! 400 lines.
//!
//! What counts: outside fenced code blocks, a backticked span that starts
//! with a top-level folder of the repository (`crates/`, `src/`, `tests/`,
//! …) is a path; a file or folder name (`groups.rs`, `engine/`) is a path
//! relative to a folder named before it in the same bullet or paragraph
//! (or to the repository); one that reads as a Rust path (`Tracker`,
//! `Tracker::from_parts`, `validate_plan()`) is a name, each of its segments
//! looked up as a whole word. Anything else (`--flags`, `x-api-key`, wire
//! paths such as `sensors[1].z`, shell commands) is prose and not checked.

use std::{
    collections::HashSet,
    fs,
    path::{Path, PathBuf},
};

/// Top-level folders whose backticked paths must exist.
const ROOTS: &[&str] = &[
    "crates/",
    "src/",
    "tests/",
    "benches/",
    "examples/",
    "checks/",
    "docs/",
    "proto/",
    "openapi/",
    "docker/",
];

/// The most lines the map may have (issue 55).
const MAX_LINES: usize = 400;

fn repository() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The backticked spans of a Markdown text outside fenced code blocks, with
/// their 1-based line numbers.
/// A backticked span: its line, the number of the bullet or paragraph it
/// is in, and its text.
struct Span {
    line: usize,
    block: usize,
    text: String,
}

/// The backticked spans of a Markdown text outside fenced code blocks.
fn backticked(markdown: &str) -> Vec<Span> {
    let mut spans = Vec::new();
    let mut fenced = false;
    let mut block = 0;
    // A span may continue on the next line of a paragraph.
    let mut open: Option<(usize, String)> = None;
    for (i, line) in markdown.lines().enumerate() {
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            open = None;
            continue;
        }
        if fenced {
            continue;
        }
        if line.trim().is_empty() || line.starts_with("- ") || line.starts_with('#') {
            block += 1;
        }
        for (k, part) in line.split('`').enumerate() {
            if k > 0 {
                match open.take() {
                    Some((at, text)) => spans.push(Span {
                        line: at,
                        block,
                        text: text.trim().to_string(),
                    }),
                    None => open = Some((i + 1, String::new())),
                }
            }
            if let Some((_, text)) = open.as_mut() {
                if k == 0 {
                    text.push(' ');
                }
                text.push_str(part);
            }
        }
    }
    spans
}

/// What a span asks to be checked.
#[derive(Debug, PartialEq)]
enum Claim<'a> {
    /// From the repository's root.
    Path(&'a str),
    /// A file or folder name, relative to a folder named before it.
    Relative(&'a str),
    Name(Vec<&'a str>),
    Prose,
}

fn claim(span: &str) -> Claim<'_> {
    if ROOTS.iter().any(|r| span.starts_with(r)) {
        return Claim::Path(span);
    }
    let file_like = |c: char| c.is_ascii_alphanumeric() || "_-./".contains(c);
    if (span.ends_with(".rs") || span.ends_with('/'))
        && !span.starts_with('/')
        && span.chars().all(file_like)
    {
        return Claim::Relative(span);
    }
    let name = span.strip_suffix("()").unwrap_or(span);
    let segments: Vec<&str> = name.split("::").collect();
    let identifier = |s: &&str| {
        let mut chars = s.chars();
        chars.next().is_some_and(|c| c.is_ascii_alphabetic())
            && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if segments.iter().all(identifier) {
        Claim::Name(segments)
    } else {
        Claim::Prose
    }
}

/// Every identifier-like word of the workspace's Rust sources, manifests
/// and proto files (comments and strings included: a name kept only in a
/// doc comment still names something a reader can find).
fn words(root: &Path) -> HashSet<String> {
    let mut words = HashSet::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        let Ok(entries) = fs::read_dir(&dir) else {
            continue;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            let name = entry.file_name().to_string_lossy().into_owned();
            if path.is_dir() {
                if !name.starts_with('.') && name != "target" && name != "node_modules" {
                    stack.push(path);
                }
                continue;
            }
            let wanted = [".rs", ".toml", ".proto"].iter().any(|e| name.ends_with(e));
            let Ok(text) = fs::read_to_string(&path)
                .map_err(|_| ())
                .and_then(|t| if wanted { Ok(t) } else { Err(()) })
            else {
                continue;
            };
            words.extend(
                text.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_'))
                    .filter(|w| !w.is_empty())
                    .map(str::to_string),
            );
        }
    }
    words
}

/// The claims of `markdown` that do not hold: a missing path or a name no
/// source mentions, each with its line.
fn false_claims(markdown: &str, root: &Path, words: &HashSet<String>) -> Vec<String> {
    let mut problems = Vec::new();
    // The folders a relative name may be in: the repository, and those
    // named earlier in the same bullet or paragraph.
    let mut bases = vec![root.to_path_buf()];
    let mut block = usize::MAX;
    for Span {
        line,
        block: b,
        text: span,
    } in backticked(markdown)
    {
        if b != block {
            block = b;
            bases.truncate(1);
        }
        match claim(&span) {
            Claim::Path(p) => {
                let path = root.join(p.trim_end_matches('/'));
                if !path.exists() {
                    problems.push(format!("line {line}: path `{p}` does not exist"));
                } else if path.is_dir() {
                    bases.push(path);
                } else if let Some(parent) = path.parent() {
                    bases.push(parent.to_path_buf());
                }
            }
            Claim::Relative(p) => {
                let found = bases
                    .iter()
                    .rev()
                    .map(|b| b.join(p.trim_end_matches('/')))
                    .find(|path| path.exists());
                match found {
                    Some(path) if path.is_dir() => bases.push(path),
                    Some(_) => {}
                    None => problems.push(format!(
                        "line {line}: `{p}` is in none of the folders named before it"
                    )),
                }
            }
            Claim::Name(segments) => {
                for s in segments.iter().filter(|s| !words.contains(**s)) {
                    problems.push(format!(
                        "line {line}: `{span}`: `{s}` occurs nowhere in the sources"
                    ));
                }
            }
            Claim::Prose => {}
        }
    }
    problems
}

#[test]
fn every_path_and_name_in_architecture_md_exists() {
    let root = repository();
    let map = fs::read_to_string(root.join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let problems = false_claims(&map, &root, &words(&root));
    assert!(
        problems.is_empty(),
        "ARCHITECTURE.md names what is not there:\n{}",
        problems.join("\n")
    );
}

#[test]
fn architecture_md_is_a_map_of_at_most_400_lines() {
    let map = fs::read_to_string(repository().join("ARCHITECTURE.md")).expect("ARCHITECTURE.md");
    let lines = map.lines().count();
    assert!(lines <= MAX_LINES, "ARCHITECTURE.md has {lines} lines");
}

/// The check itself: a renamed type and a moved file are caught with
/// their lines; fenced blocks, prose and a span wrapped over two lines
/// (which Markdown joins with a space) are left alone.
#[test]
fn a_missing_path_or_name_is_reported_with_its_line() {
    let root = repository();
    let words: HashSet<String> = ["Tracker", "from_parts"]
        .into_iter()
        .map(String::from)
        .collect();
    let doc = "# Map\n\
        `Tracker::from_parts` in `crates/algo/src/`: `tracking/`, `window.rs`; `--api-keys`.\n\
        ```\nnot `Checked` here\n```\n\
        `TrackerGone` lives in `src/no_such_file.rs`, beside `cargo tree\n\
        -p algo` and `sensors[1].z`.\n\
        - `window.rs` again, in a bullet that names no folder.\n";
    assert_eq!(
        false_claims(doc, &root, &words),
        vec![
            "line 6: `TrackerGone`: `TrackerGone` occurs nowhere in the sources".to_string(),
            "line 6: path `src/no_such_file.rs` does not exist".to_string(),
            "line 8: `window.rs` is in none of the folders named before it".to_string(),
        ]
    );
}
