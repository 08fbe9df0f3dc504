//! The check every command runs before it reads or writes anything: no output may be the
//! same file as an input of the run or as another of its outputs.
//!
//! "The same file" is decided the way the file system decides it, not by the spelling of
//! the path: paths are compared after following symlinks and resolving `.` and `..`
//! ([`FileKey`]), and files that exist also by device and inode, so a hard link counts.
//! A frame pattern is checked as the list of files it stands for (the caller expands it
//! over the frames that exist), so `-o 'f_1###.vdb'` is caught overwriting input frame
//! 1001 before frame 1 is written.
//!
//! Streams — devices, FIFOs, the process's own stdout — are written into, not replaced
//! ([`crate::output`]), so nothing on them can be lost; they never clash (two outputs
//! into `/dev/null` are fine).

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use crate::output::Target;

/// What identifies the file a path names.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FileKey {
    /// The canonical path of the file; for one that does not exist yet, of its directory
    /// plus its name. `None` when not even the directory exists.
    canonical: Option<PathBuf>,
    /// Device and inode of a file that exists.
    id: Option<(u64, u64)>,
    /// Written into rather than replaced (see the module docs).
    stream: bool,
}

impl FileKey {
    pub fn of(path: &Path) -> FileKey {
        let target = Target::of(path);
        let stream = target.as_ref().is_ok_and(Target::is_stream);
        let end = match target {
            Ok(Target::Replace(end)) | Ok(Target::Into { path: end, .. }) => end,
            Err(_) => path.to_path_buf(),
        };
        let canonical = end.canonicalize().ok().or_else(|| {
            let name = end.file_name()?;
            let dir = match end.parent() {
                Some(d) if !d.as_os_str().is_empty() => d,
                _ => Path::new("."),
            };
            dir.canonicalize().ok().map(|d| d.join(name))
        });
        FileKey {
            canonical,
            id: device_and_inode(&end),
            stream,
        }
    }

    /// Whether both keys name one file.
    pub fn same(&self, other: &FileKey) -> bool {
        (self.canonical.is_some() && self.canonical == other.canonical)
            || (self.id.is_some() && self.id == other.id)
    }

    /// Whether the file is a stream (never a clash).
    pub fn is_stream(&self) -> bool {
        self.stream
    }
}

#[cfg(unix)]
fn device_and_inode(p: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn device_and_inode(_: &Path) -> Option<(u64, u64)> {
    None
}

/// An output that would overwrite a file of the run.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Clash {
    #[error("{}: {role} would overwrite the {input_role} {}, an input of this run", output.display(), input.display())]
    Input {
        output: PathBuf,
        role: String,
        input: PathBuf,
        input_role: String,
    },
    #[error("{}: {role} and {other_role} name the same file{}", output.display(), same_as(output, other))]
    Outputs {
        output: PathBuf,
        role: String,
        other: PathBuf,
        other_role: String,
    },
}

fn same_as(a: &Path, b: &Path) -> String {
    if a == b {
        String::new()
    } else {
        format!(" ({})", b.display())
    }
}

struct Entry {
    role: String,
    path: PathBuf,
    key: FileKey,
}

impl Entry {
    fn new(role: String, path: &Path) -> Entry {
        Entry {
            role,
            key: FileKey::of(path),
            path: path.to_path_buf(),
        }
    }
}

/// The inputs and outputs of one run, checked together with [`Guard::check`].
#[derive(Default)]
pub struct Guard {
    inputs: Vec<Entry>,
    outputs: Vec<Entry>,
}

impl Guard {
    pub fn new() -> Guard {
        Guard::default()
    }

    /// A file the run reads; `role` names it in the message (`brick file`, `mesh`,
    /// `frame 12`).
    pub fn input(&mut self, role: impl Into<String>, path: &Path) -> &mut Guard {
        self.inputs.push(Entry::new(role.into(), path));
        self
    }

    /// A file the run writes; `role` is how the user named it (`-o`, `--save-state`,
    /// `-o (frame 3)`).
    pub fn output(&mut self, role: impl Into<String>, path: &Path) -> &mut Guard {
        self.outputs.push(Entry::new(role.into(), path));
        self
    }

    /// The first clash, in the order the outputs were given: an output that is an input,
    /// then one that is an earlier output.
    pub fn check(&self) -> Result<(), Clash> {
        fn find<'a>(
            by_path: &HashMap<&Path, &'a Entry>,
            by_id: &HashMap<(u64, u64), &'a Entry>,
            key: &FileKey,
        ) -> Option<&'a Entry> {
            key.canonical
                .as_deref()
                .and_then(|c| by_path.get(c).copied())
                .or_else(|| key.id.and_then(|id| by_id.get(&id).copied()))
        }
        let mut by_path: HashMap<&Path, &Entry> = HashMap::new();
        let mut by_id: HashMap<(u64, u64), &Entry> = HashMap::new();
        for e in self.inputs.iter().filter(|e| !e.key.stream) {
            if let Some(c) = &e.key.canonical {
                by_path.entry(c).or_insert(e);
            }
            if let Some(id) = e.key.id {
                by_id.entry(id).or_insert(e);
            }
        }
        for out in self.outputs.iter().filter(|e| !e.key.stream) {
            if let Some(input) = find(&by_path, &by_id, &out.key) {
                return Err(Clash::Input {
                    output: out.path.clone(),
                    role: out.role.clone(),
                    input: input.path.clone(),
                    input_role: input.role.clone(),
                });
            }
        }
        let mut seen_path: HashMap<&Path, &Entry> = HashMap::new();
        let mut seen_id: HashMap<(u64, u64), &Entry> = HashMap::new();
        for out in self.outputs.iter().filter(|e| !e.key.stream) {
            if let Some(other) = find(&seen_path, &seen_id, &out.key) {
                return Err(Clash::Outputs {
                    output: out.path.clone(),
                    role: out.role.clone(),
                    other: other.path.clone(),
                    other_role: other.role.clone(),
                });
            }
            if let Some(c) = &out.key.canonical {
                seen_path.insert(c, out);
            }
            if let Some(id) = out.key.id {
                seen_id.insert(id, out);
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_output_over_an_input_is_named_with_both_roles() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.vdb");
        std::fs::write(&a, b"x").expect("write");
        std::fs::create_dir(dir.path().join("sub")).expect("mkdir");
        let mut g = Guard::new();
        g.input("frame 1001", &a)
            .output("-o (frame 1)", &dir.path().join("sub/../a.vdb"));
        let e = g.check().expect_err("clash");
        assert!(
            e.to_string()
                .contains("-o (frame 1) would overwrite the frame 1001"),
            "{e}"
        );
    }

    #[test]
    fn two_outputs_into_one_file_clash_but_not_into_a_device() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut g = Guard::new();
        g.output("-o", &dir.path().join("x.png"))
            .output("--save-state", &dir.path().join("x.png"));
        let e = g.check().expect_err("clash");
        assert!(
            e.to_string()
                .contains("--save-state and -o name the same file"),
            "{e}"
        );
        let mut g = Guard::new();
        g.output("-o", Path::new("/dev/null"))
            .output("--save-state", Path::new("/dev/null"))
            .input("points", Path::new("/dev/null"));
        assert_eq!(g.check(), Ok(()));
    }

    #[cfg(unix)]
    #[test]
    fn links_hard_and_soft_and_dangling_are_seen_through() {
        let dir = tempfile::tempdir().expect("tempdir");
        let a = dir.path().join("a.qbk");
        std::fs::write(&a, b"x").expect("write");
        let hard = dir.path().join("hard.qbk");
        std::fs::hard_link(&a, &hard).expect("hard link");
        let soft = dir.path().join("soft.png");
        std::os::unix::fs::symlink("a.qbk", &soft).expect("symlink");
        for out in [&hard, &soft] {
            let mut g = Guard::new();
            g.input("brick file", &a).output("-o", out);
            assert!(g.check().is_err(), "{}", out.display());
        }
        // A dangling link names the file it would create.
        let dangling = dir.path().join("later.png");
        std::os::unix::fs::symlink("new.png", &dangling).expect("symlink");
        let mut g = Guard::new();
        g.output("-o", &dangling)
            .output("--plot", &dir.path().join("new.png"));
        assert!(g.check().is_err());
    }

    #[test]
    fn many_frames_are_checked_in_linear_time() {
        let dir = tempfile::tempdir().expect("tempdir");
        let mut g = Guard::new();
        for i in 0..5000 {
            g.input(
                format!("frame {i}"),
                &dir.path().join(format!("f_{i:04}.qbk")),
            );
            g.output(
                format!("-o (frame {i})"),
                &dir.path().join(format!("p_{i:04}.png")),
            );
        }
        assert_eq!(g.check(), Ok(()));
        g.output("--save-state", &dir.path().join("f_4999.qbk"));
        assert!(g.check().is_err());
    }
}
