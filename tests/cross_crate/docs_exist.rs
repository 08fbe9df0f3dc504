//! The documents stay true to the code: each `*.md` path named in the README, in `docs/` or
//! in a source comment exists (relative to the repository root, or to the referring
//! document's folder), and every command-line flag the programs accept is named in the
//! README or the documents holding the flag tables (`docs/cli.md`, `docs/window.md`).

use crate::common;
use std::path::{Path, PathBuf};

/// Text files to scan: the top-level Markdown, `docs/`, and every Rust source of the crates
/// and tests (except this file, whose examples name documents that do not exist).
fn sources(root: &Path) -> Vec<PathBuf> {
    let mut out = vec![root.join("README.md")];
    let mut stack: Vec<PathBuf> = [
        "docs",
        "files",
        "format",
        "preprocess",
        "viewer",
        "tests",
        "src",
    ]
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

/// The documents that hold the command-line flags: the README names the ones that matter
/// most, `docs/cli.md` every command's flag table, `docs/window.md` the window's.
const FLAG_DOCUMENTS: [&str; 3] = ["README.md", "docs/cli.md", "docs/window.md"];

/// The `(binary, subcommand)` pairs whose `--help` the flag check reads.
const COMMANDS: [(&str, &[&str]); 9] = [
    ("qbricks-bake", &["bake"]),
    ("qbricks-bake", &["inspect"]),
    ("qbricks-view", &[]),
    ("qbricks-view", &["render"]),
    ("qbricks-view", &["probe"]),
    ("qbricks-view", &["info"]),
    ("qbricks-lab", &["synth"]),
    ("qbricks-lab", &["accuracy"]),
    ("qbricks-lab", &["bench"]),
];

/// The flags of `COMMANDS` that `docs` (the documents' text) does not name, as
/// `binary subcommand --flag`, and how many flags were checked.
fn undocumented_flags(docs: &str) -> (Vec<String>, usize) {
    let mut missing = Vec::new();
    let mut checked = 0;
    for (bin, sub) in COMMANDS {
        let out = std::process::Command::new(common::bin(bin))
            .args(sub)
            .arg("--help")
            .output()
            .expect("run --help");
        assert!(out.status.success(), "{bin} {sub:?} --help failed");
        for flag in long_flags(&String::from_utf8_lossy(&out.stdout)) {
            checked += 1;
            let short_output = flag == "--output" && docs.contains(" -o ");
            if !names_flag(docs, &flag) && !short_output {
                missing.push(format!("{bin} {} {flag}", sub.join(" ")));
            }
        }
    }
    (missing, checked)
}

/// A user reads the README and the documents it links, not `--help`: a flag added to a
/// command but documented nowhere is a feature nobody finds. Every flag must be named in
/// the README or in the documents that hold the flag tables (`FLAG_DOCUMENTS`).
/// `-o`/`--output` may be written in its short form.
#[test]
fn readme_names_every_flag_of_every_command() {
    let root = common::root();
    let docs: String = FLAG_DOCUMENTS
        .iter()
        .map(|d| std::fs::read_to_string(root.join(d)).unwrap_or_else(|e| panic!("{d}: {e}")))
        .collect::<Vec<_>>()
        .join("\n");
    let (missing, checked) = undocumented_flags(&docs);
    assert!(
        checked > 20,
        "only {checked} flags found: the --help scan is broken"
    );
    assert!(
        missing.is_empty(),
        "documented in none of {FLAG_DOCUMENTS:?}:\n{}",
        missing.join("\n")
    );
    // The check is real: a flag named in no document is reported (with no text, all are).
    let (without_docs, _) = undocumented_flags("");
    assert_eq!(
        without_docs.len(),
        checked,
        "with no text, every flag is missing"
    );
}

/// The README links the documents that hold the flag tables, so a user finds them.
#[test]
fn readme_links_the_flag_documents() {
    let readme = std::fs::read_to_string(common::root().join("README.md")).expect("README.md");
    for doc in &FLAG_DOCUMENTS[1..] {
        assert!(
            readme.contains(&format!("]({doc}")),
            "README.md does not link {doc}"
        );
    }
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

/// GitHub's anchor of a Markdown heading: lower case, punctuation other than `-` and `_`
/// dropped, spaces as `-`.
fn anchor_of(heading: &str) -> String {
    heading
        .trim()
        .to_lowercase()
        .chars()
        .filter(|c| c.is_alphanumeric() || *c == ' ' || *c == '-' || *c == '_')
        .map(|c| if c == ' ' { '-' } else { c })
        .collect()
}

/// The headings of a Markdown text (outside code blocks), as written.
fn headings(text: &str) -> Vec<String> {
    let mut in_code = false;
    let mut out = Vec::new();
    for line in text.lines() {
        if line.trim_start().starts_with("```") {
            in_code = !in_code;
            continue;
        }
        if !in_code && line.starts_with('#') {
            out.push(line.trim_start_matches('#').trim().to_string());
        }
    }
    out
}

/// Links to a section of a document, `doc.md#anchor`, and prose references to one,
/// `` `docs/doc.md`, "Section title" ``: (document, anchor or title, is a title).
fn section_references(text: &str) -> Vec<(String, String, bool)> {
    let mut out = Vec::new();
    for w in text.split(|c: char| c.is_whitespace() || "()[]<>\"',;|*`".contains(c)) {
        if let Some((doc, anchor)) = w.split_once(".md#") {
            if !doc.starts_with("http") && !anchor.is_empty() {
                out.push((format!("{doc}.md"), anchor.to_string(), false));
            }
        }
    }
    // `docs/x.md`, "Title" (a title in quotes right after the document's name).
    let mut rest = text;
    while let Some(i) = rest.find(".md`, \"") {
        let before = &rest[..i];
        let start = before.rfind('`').map_or(0, |s| s + 1);
        let doc = format!("{}.md", &before[start..]);
        let after = &rest[i + ".md`, \"".len()..];
        if let Some(end) = after.find('"') {
            out.push((doc, after[..end].to_string(), true));
        }
        rest = &rest[i + 1..];
    }
    out
}

/// A link into a section that was renamed or moved lands at the top of the document; a
/// "see docs/x.md, section" that names a section it does not have sends the reader
/// looking for it.
#[test]
fn every_referenced_section_exists() {
    let root = common::root();
    let mut missing = Vec::new();
    let mut seen = 0;
    for file in sources(&root) {
        let Ok(text) = std::fs::read_to_string(&file) else {
            continue;
        };
        let here = file.parent().unwrap_or(&root);
        for (doc, target, is_title) in section_references(&text) {
            let path = [here.join(&doc), root.join(&doc)]
                .into_iter()
                .find(|p| p.exists());
            let Some(path) = path else {
                continue; // every_referenced_document_exists reports it
            };
            seen += 1;
            let heads = headings(&std::fs::read_to_string(&path).unwrap_or_default());
            let found = if is_title {
                heads.iter().any(|h| h.contains(&target))
            } else {
                heads.iter().any(|h| anchor_of(h) == target)
            };
            if !found {
                missing.push(format!(
                    "{}: {doc} has no section {target:?}",
                    file.display()
                ));
            }
        }
    }
    assert!(seen > 0, "no section references found: the scan is broken");
    assert!(
        missing.is_empty(),
        "missing sections:\n{}",
        missing.join("\n")
    );
}

#[test]
fn section_scan_finds_anchors_and_quoted_titles() {
    assert_eq!(anchor_of("Files (`files/`)"), "files-files");
    assert_eq!(
        anchor_of("Speed, structure, open, bake, frames (format 3)"),
        "speed-structure-open-bake-frames-format-3"
    );
    assert_eq!(
        section_references(
            "see [d](docs/a.md#x-y) and (see `docs/design.md`, \"Sampling strategies\")"
        ),
        vec![
            ("docs/a.md".to_string(), "x-y".to_string(), false),
            (
                "docs/design.md".to_string(),
                "Sampling strategies".to_string(),
                true
            )
        ]
    );
}

/// Every `fn` of the workspace with whether it is `pub` (without a restriction), and the
/// names of its modules (`mod x` and the files and folders that hold them).
fn functions(root: &Path) -> (std::collections::HashMap<String, bool>, Vec<String>) {
    let mut fns: std::collections::HashMap<String, bool> = std::collections::HashMap::new();
    let mut modules = Vec::new();
    for file in sources(root)
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
    {
        if let Some(stem) = file.file_stem() {
            modules.push(stem.to_string_lossy().into_owned());
        }
        if let Some(dir) = file.parent().and_then(Path::file_name) {
            modules.push(dir.to_string_lossy().into_owned());
        }
        let text = std::fs::read_to_string(file).unwrap_or_default();
        for line in text.lines() {
            let t = line.trim_start();
            if let Some(m) = t.split("mod ").nth(1).filter(|_| t.contains("mod ")) {
                let name: String = m
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                modules.push(name);
            }
            let Some(i) = t.find("fn ") else { continue };
            let head = &t[..i];
            if !head.split_whitespace().all(|w| {
                w.starts_with("pub") || ["const", "async", "unsafe", "extern"].contains(&w)
            }) {
                continue;
            }
            let name: String = t[i + 3..]
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if name.is_empty() {
                continue;
            }
            let public = head.split_whitespace().any(|w| w == "pub");
            let e = fns.entry(name).or_insert(false);
            *e |= public;
        }
    }
    (fns, modules)
}

/// `` `a::b::name` `` words of a document whose last part is a snake_case name.
fn named_functions(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .filter(|w| w.contains("::") && !w.contains(' '))
        .filter_map(|w| {
            let w = w.split('(').next().unwrap_or(w);
            let last = w.rsplit("::").next()?;
            (last.starts_with(|c: char| c.is_ascii_lowercase())
                && last
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_'))
            .then(|| w.to_string())
        })
        .collect()
}

/// A document that tells users to call a function that is gone costs them the time to
/// find out; one that tells them to call a function private to its crate, too. Every
/// `` `path::function` `` the documents name, whose first part is one of the workspace's
/// crates or types, must be a function of the workspace; in the documents written for
/// users of the programs and libraries (the README, the command-line, window and view-state
/// references and the `.qbk` format's), a `pub` one. (The design
/// notes may name internal functions: they are for the people changing them.)
#[test]
fn every_function_the_documents_name_exists_and_users_can_call() {
    let root = common::root();
    let (fns, modules) = functions(&root);
    let ours = [
        "format",
        "files",
        "preprocess",
        "viewer",
        "qbricks_viewer",
        "qbricks_preprocess",
    ];
    let for_users = [
        root.join("README.md"),
        root.join("docs/format.md"),
        root.join("docs/cli.md"),
        root.join("docs/window.md"),
        root.join("docs/view-state.md"),
    ];
    let mut wrong = Vec::new();
    let mut seen = 0;
    for file in sources(&root)
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "md"))
    {
        let text = std::fs::read_to_string(file).unwrap_or_default();
        for path in named_functions(&text) {
            let first = path.split("::").next().unwrap_or("");
            let is_type = first.starts_with(|c: char| c.is_ascii_uppercase());
            if !ours.contains(&first) && !is_type {
                continue;
            }
            let name = path.rsplit("::").next().unwrap_or("");
            match fns.get(name) {
                Some(true) => seen += 1,
                Some(false) if !for_users.contains(file) => seen += 1,
                Some(false) => wrong.push(format!("{}: {path} is not pub", file.display())),
                // A module (`format::kd`), or a type of another crate (`Vec::new`).
                None if is_type || modules.iter().any(|m| m == name) => {}
                None => wrong.push(format!("{}: {path} does not exist", file.display())),
            }
        }
    }
    assert!(seen > 10, "only {seen} functions found: the scan is broken");
    assert!(
        wrong.is_empty(),
        "documents name functions users cannot call:\n{}",
        wrong.join("\n")
    );
}
