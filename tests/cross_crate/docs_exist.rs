//! The documents stay true to the code: each `*.md` path named in the README, in `docs/` or
//! in a source comment exists (relative to the repository root, or to the referring
//! document's folder), and the README names every command-line flag the programs accept.

use crate::common;
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
                && !p.ends_with("tests/cross_crate/docs_exist.rs")
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
    let root = common::root();
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

/// Targets of Markdown image links, `![alt](path)`.
fn image_links(text: &str) -> Vec<String> {
    text.split("](")
        .skip(1)
        .zip(text.split("](").map(|before| {
            before
                .rfind('[')
                .is_some_and(|i| before[..i].ends_with('!'))
        }))
        .filter(|(_, is_image)| *is_image)
        .filter_map(|(after, _)| after.split(')').next())
        .filter(|p| !p.starts_with("http"))
        .map(str::to_string)
        .collect()
}

/// A picture in the README that is not in the repository shows as a broken link on the
/// project page.
#[test]
fn every_image_in_the_documents_exists() {
    let root = common::root();
    let mut missing = Vec::new();
    let mut seen = 0;
    for file in sources(&root)
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
    {
        let text = std::fs::read_to_string(file).expect("read document");
        let here = file.parent().unwrap_or(&root);
        for link in image_links(&text) {
            seen += 1;
            if !here.join(&link).exists() {
                missing.push(format!("{}: {link}", file.display()));
            }
        }
    }
    assert!(seen > 0, "no image links found: the scan is broken");
    assert!(
        missing.is_empty(),
        "missing images:\n{}",
        missing.join("\n")
    );
}

#[test]
fn image_scan_finds_image_links_only() {
    assert_eq!(
        image_links("![a](x.png) [doc](a.md), ![pic](docs/p.png) ![q](http://x/y.png)"),
        vec!["x.png", "docs/p.png"]
    );
}

/// Long flags (`--name`) in a `--help` text, except the ones clap adds to every command.
fn long_flags(help: &str) -> Vec<String> {
    let mut flags: Vec<String> = help
        .split(|c: char| c.is_whitespace() || ",=[]<>".contains(c))
        .filter(|w| w.starts_with("--") && w[2..].starts_with(|c: char| c.is_ascii_lowercase()))
        .map(|w| {
            w.trim_end_matches(|c: char| !c.is_ascii_alphanumeric())
                .to_string()
        })
        .filter(|w| w != "--help" && w != "--version")
        .collect();
    flags.sort();
    flags.dedup();
    flags
}

/// Whether `text` holds `flag` as a whole word (`--iso` must not be found inside `--iso-field`).
fn names_flag(text: &str, flag: &str) -> bool {
    text.match_indices(flag).any(|(i, _)| {
        !text[i + flag.len()..].starts_with(|c: char| c.is_ascii_alphanumeric() || c == '-')
    })
}

/// A user reads the README, not `--help`: a flag added to a command but not to the README is
/// a feature nobody finds. `-o`/`--output` may be written in its short form.
#[test]
fn readme_names_every_flag_of_every_command() {
    let readme = std::fs::read_to_string(common::root().join("README.md")).expect("README.md");
    let commands: [(&str, &[&str]); 9] = [
        ("qbricks-bake", &["bake"]),
        ("qbricks-bake", &["synth"]),
        ("qbricks-bake", &["inspect"]),
        ("qbricks-bake", &["accuracy"]),
        ("qbricks-view", &[]),
        ("qbricks-view", &["render"]),
        ("qbricks-view", &["probe"]),
        ("qbricks-view", &["info"]),
        ("qbricks-view", &["bench"]),
    ];
    let mut missing = Vec::new();
    let mut checked = 0;
    for (bin, sub) in commands {
        let out = std::process::Command::new(common::bin(bin))
            .args(sub)
            .arg("--help")
            .output()
            .expect("run --help");
        assert!(out.status.success(), "{bin} {sub:?} --help failed");
        for flag in long_flags(&String::from_utf8_lossy(&out.stdout)) {
            checked += 1;
            let short_output = flag == "--output" && readme.contains(" -o ");
            if !names_flag(&readme, &flag) && !short_output {
                missing.push(format!("{bin} {} {flag}", sub.join(" ")));
            }
        }
    }
    assert!(
        checked > 20,
        "only {checked} flags found: the --help scan is broken"
    );
    assert!(
        missing.is_empty(),
        "README.md does not mention:\n{}",
        missing.join("\n")
    );
}

#[test]
fn flag_scan_finds_long_flags_and_whole_words() {
    assert_eq!(
        long_flags(
            "  -o, --output <OUTPUT>  out\n      --iso-field <F>  [default: q]\n  -h, --help"
        ),
        vec!["--iso-field", "--output"]
    );
    assert!(names_flag("use --iso 3", "--iso"));
    assert!(!names_flag("use --iso-field q", "--iso"));
}
