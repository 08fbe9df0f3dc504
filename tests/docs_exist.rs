//! The repository holds every document it refers to: each `*.md` path named in the README,
//! in `docs/` or in a source comment exists (relative to the repository root, or to the
//! referring document's folder).

mod util;

use std::path::{Path, PathBuf};

/// Text files to scan: the top-level Markdown, `docs/`, and every Rust source of the crates
/// and tests (except this file, whose examples name documents that do not exist).
fn sources(root: &Path) -> Vec<PathBuf> {
    let mut out = vec![root.join("README.md")];
    let mut stack: Vec<PathBuf> = ["docs", "format", "preprocess", "viewer", "tests", "src"]
        .iter()
        .map(|d| root.join(d))
        .collect();
    while let Some(dir) = stack.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                if p.file_name().is_some_and(|n| n != "target") {
                    stack.push(p);
                }
            } else if p.extension().is_some_and(|x| x == "rs" || x == "md")
                && !p.ends_with("tests/docs_exist.rs")
            {
                out.push(p);
            }
        }
    }
    out
}

/// `*.md` words of `text`, without surrounding punctuation or a `#anchor`.
fn md_references(text: &str) -> Vec<String> {
    text.split(|c: char| c.is_whitespace() || "`()[]<>\"',;|*".contains(c))
        .map(|w| w.split('#').next().unwrap_or(""))
        .map(|w| w.trim_end_matches(['.', ':']))
        .filter(|w| w.ends_with(".md") && !w.starts_with("http"))
        .map(str::to_string)
        .collect()
}

#[test]
fn every_referenced_document_exists() {
    let root = util::root();
    let mut missing = Vec::new();
    let mut seen = 0;
    for file in sources(&root) {
        let Ok(text) = std::fs::read_to_string(&file) else {
            continue;
        };
        let here = file.parent().unwrap_or(&root);
        for r in md_references(&text) {
            seen += 1;
            if !root.join(&r).exists() && !here.join(&r).exists() {
                missing.push(format!("{}: {r}", file.display()));
            }
        }
    }
    assert!(seen > 0, "no document references found: the scan is broken");
    assert!(
        missing.is_empty(),
        "missing documents:\n{}",
        missing.join("\n")
    );
}

#[test]
fn reference_scan_finds_paths_in_prose_and_links() {
    assert_eq!(
        md_references("see DESIGN.md, and [x](docs/design.md#a-b) or `docs/y.md`."),
        vec!["DESIGN.md", "docs/design.md", "docs/y.md"]
    );
}
