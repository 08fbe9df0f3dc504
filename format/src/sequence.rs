//! Frame sequences: file-name patterns (`fluid_data_####.vdb`, `frame_%04d.qbk`), the frames
//! of a pattern that exist on disk, and the JSON manifest `qbricks-bake bake` writes next to
//! a baked sequence.
//!
//! It lives in `format` because both programs speak it: `qbricks-bake` writes the frames
//! and the manifest, `qbricks-view` finds the frames by the same pattern rules and takes the
//! sequence-wide field ranges from the manifest, so one colour map fits every frame.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use files::input::{read_whole, InputErrorKind, Limits};

/// A file name with one frame-number placeholder: a run of `N` `#` (the number padded with
/// zeros to N digits) or `%0Nd` / `%d` (printf style). Only the file name may hold it, not
/// the directories.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FramePattern {
    dir: PathBuf,
    prefix: String,
    suffix: String,
    width: usize,
}

/// Why a pattern is not usable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PatternError {
    #[error("{0}: more than one frame-number placeholder (#### or %04d) in the file name")]
    Several(String),
    #[error("{0}: a frame-number placeholder (#### or %04d) in a directory name is not supported")]
    InDirectory(String),
    #[error("{0}: frame-number width must be 1 to 18 digits")]
    Width(String),
}

/// Placeholder in `name`: (start, end, width) in bytes.
fn placeholder(name: &str) -> Result<Option<(usize, usize, usize)>, ()> {
    let mut found = None;
    let b = name.as_bytes();
    let mut i = 0;
    while i < b.len() {
        let hit = if b[i] == b'#' {
            let n = b[i..].iter().take_while(|&&c| c == b'#').count();
            Some((i, i + n, n))
        } else if b[i] == b'%' {
            // %d or %0Nd (N one or two digits).
            let rest = &name[i + 1..];
            if rest.starts_with('d') {
                Some((i, i + 2, 1))
            } else if let Some(r) = rest.strip_prefix('0') {
                let digits = r.bytes().take_while(u8::is_ascii_digit).count();
                if (1..=2).contains(&digits) && r[digits..].starts_with('d') {
                    let w: usize = r[..digits].parse().map_err(|_| ())?;
                    Some((i, i + 3 + digits, w))
                } else {
                    None
                }
            } else {
                None
            }
        } else {
            None
        };
        match hit {
            Some(h) => {
                if found.is_some() {
                    return Err(());
                }
                found = Some(h);
                i = h.1;
            }
            None => i += 1,
        }
    }
    Ok(found)
}

impl FramePattern {
    /// The pattern in `path`, `Ok(None)` when it has no placeholder.
    pub fn parse(path: &Path) -> Result<Option<FramePattern>, PatternError> {
        let shown = path.display().to_string();
        if let Some(parent) = path.parent() {
            for c in parent.components() {
                let s = c.as_os_str().to_string_lossy();
                if placeholder(&s).map_or(true, |p| p.is_some()) {
                    return Err(PatternError::InDirectory(shown));
                }
            }
        }
        let Some(name) = path.file_name().map(|n| n.to_string_lossy().into_owned()) else {
            return Ok(None);
        };
        let Some((start, end, width)) =
            placeholder(&name).map_err(|()| PatternError::Several(shown.clone()))?
        else {
            return Ok(None);
        };
        if !(1..=18).contains(&width) {
            return Err(PatternError::Width(shown));
        }
        Ok(Some(FramePattern {
            dir: path.parent().map(Path::to_path_buf).unwrap_or_default(),
            prefix: name[..start].to_string(),
            suffix: name[end..].to_string(),
            width,
        }))
    }

    /// The directory the frames live in (empty: the current directory).
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// Path of frame `frame`.
    pub fn path(&self, frame: u64) -> PathBuf {
        self.dir.join(format!(
            "{}{:0w$}{}",
            self.prefix,
            frame,
            self.suffix,
            w = self.width
        ))
    }

    /// A path next to the frames: the pattern with the placeholder replaced by `word` and
    /// the extension by `ext` (`frame_####.qbk` → `frame_sequence.json`).
    pub(crate) fn sibling(&self, word: &str, ext: &str) -> PathBuf {
        let name = format!("{}{}{}", self.prefix, word, self.suffix);
        self.dir.join(Path::new(&name).with_extension(ext))
    }

    /// Where the manifest of a sequence with these file names is written and looked for:
    /// `frame_####.qbk` → `frame_sequence.json`.
    pub fn manifest_path(&self) -> PathBuf {
        self.sibling("sequence", "json")
    }

    /// The frame number a file name stands for: the prefix, then digits (exactly `width`,
    /// or more without a leading zero, as `%04d` prints 12345), then the suffix.
    pub(crate) fn frame_of(&self, name: &str) -> Option<u64> {
        let digits = name
            .strip_prefix(&self.prefix)?
            .strip_suffix(&self.suffix)?;
        if digits.is_empty()
            || !digits.bytes().all(|c| c.is_ascii_digit())
            || digits.len() < self.width
            || (digits.len() > self.width && digits.starts_with('0'))
            || digits.len() > 18
        {
            return None;
        }
        digits.parse().ok()
    }

    /// Frames present on disk, sorted by number (regular files and links to them).
    pub fn scan(&self) -> std::io::Result<Vec<(u64, PathBuf)>> {
        let dir = if self.dir.as_os_str().is_empty() {
            Path::new(".")
        } else {
            &self.dir
        };
        let mut out = Vec::new();
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if let Some(f) = self.frame_of(&name) {
                if std::fs::metadata(entry.path()).is_ok_and(|m| m.is_file()) {
                    out.push((f, self.path(f)));
                }
            }
        }
        out.sort();
        out.dedup_by_key(|f| f.0);
        Ok(out)
    }
}

/// One baked frame in the manifest. Paths are as given on the command line.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ManifestFrame {
    pub frame: u64,
    pub input: String,
    pub output: String,
    pub leaf_cells: u64,
    /// The frame's own range of each field.
    pub fields: Vec<FieldRange>,
}

/// A frame that could not be baked.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ManifestFailure {
    pub frame: u64,
    pub input: String,
    pub error: String,
}

/// Range of one field (of one frame, or over every baked frame: one colour map fits the
/// whole sequence).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FieldRange {
    pub name: String,
    pub min: f32,
    pub max: f32,
}

/// The sequence manifest (`<prefix>sequence<suffix>.json` next to the outputs). Readers
/// ignore keys they do not know, so the manifest can grow without breaking older viewers.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Manifest {
    pub input_pattern: String,
    pub output_pattern: String,
    /// Baked frames by number.
    pub frames: Vec<ManifestFrame>,
    /// Frames that exist but failed.
    pub failed: Vec<ManifestFailure>,
    /// Numbers inside the baked range with no input file.
    pub missing: Vec<u64>,
    /// Per field, min and max over all baked frames, in the first frame's field order.
    pub fields: Vec<FieldRange>,
}

/// Largest manifest [`Manifest::load`] reads: a few hundred bytes per frame, so this is
/// tens of thousands of frames with many fields.
pub(crate) const MAX_MANIFEST_BYTES: u64 = 64 << 20;

/// Why a manifest could not be read.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct ManifestError {
    pub path: PathBuf,
    pub kind: ManifestErrorKind,
}

#[derive(Debug, thiserror::Error)]
pub enum ManifestErrorKind {
    #[error("{0}")]
    Input(InputErrorKind),
    #[error("not a sequence manifest: {0}")]
    Parse(serde_json::Error),
    #[error("field {name:?}: expected min ≤ max (finite), found {min} … {max}")]
    Range { name: String, min: f32, max: f32 },
}

impl Manifest {
    /// The manifest of the sequence whose frames match `pattern`
    /// ([`FramePattern::manifest_path`]), `Ok(None)` when there is none.
    pub fn find(pattern: &FramePattern) -> Result<Option<(PathBuf, Manifest)>, ManifestError> {
        let path = pattern.manifest_path();
        if !path.exists() {
            return Ok(None);
        }
        Manifest::load(&path).map(|m| Some((path, m)))
    }

    /// Reads and checks a manifest (at most [`MAX_MANIFEST_BYTES`]).
    pub(crate) fn load(path: &Path) -> Result<Manifest, ManifestError> {
        let err = |kind| ManifestError {
            path: path.to_path_buf(),
            kind,
        };
        let bytes = read_whole(path, Limits::both(MAX_MANIFEST_BYTES))
            .map_err(|e| err(ManifestErrorKind::Input(e.kind)))?;
        let m: Manifest =
            serde_json::from_slice(&bytes).map_err(|e| err(ManifestErrorKind::Parse(e)))?;
        // A range the viewer would build a colour map from must be usable as one.
        for f in &m.fields {
            if !(f.min.is_finite() && f.max.is_finite() && f.min <= f.max) {
                return Err(err(ManifestErrorKind::Range {
                    name: f.name.clone(),
                    min: f.min,
                    max: f.max,
                }));
            }
        }
        Ok(m)
    }
}

/// Global field ranges over `frames` (fields in order of first appearance).
pub fn global_ranges(frames: &[ManifestFrame]) -> Vec<FieldRange> {
    let mut out: Vec<FieldRange> = Vec::new();
    for f in frames.iter().flat_map(|fr| &fr.fields) {
        match out.iter_mut().find(|r| r.name == f.name) {
            Some(r) => {
                r.min = r.min.min(f.min);
                r.max = r.max.max(f.max);
            }
            None => out.push(FieldRange {
                name: f.name.clone(),
                min: f.min,
                max: f.max,
            }),
        }
    }
    out
}

/// Frame numbers between the first and last of `present` (sorted) that are not in it.
pub fn gaps(present: &[u64]) -> Vec<u64> {
    let mut out = Vec::new();
    for w in present.windows(2) {
        // Cap the report: a pattern can match frame 1 and frame 10⁹.
        out.extend((w[0] + 1..w[1]).take(10_000 - out.len().min(10_000)));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patterns() {
        let p = FramePattern::parse(Path::new("cache/fluid_data_####.vdb"))
            .unwrap()
            .unwrap();
        assert_eq!(p.path(7), PathBuf::from("cache/fluid_data_0007.vdb"));
        assert_eq!(p.path(12345), PathBuf::from("cache/fluid_data_12345.vdb"));
        assert_eq!(p.frame_of("fluid_data_0012.vdb"), Some(12));
        assert_eq!(p.frame_of("fluid_data_12345.vdb"), Some(12345));
        assert_eq!(p.frame_of("fluid_data_012.vdb"), None);
        assert_eq!(p.frame_of("fluid_data_01234.vdb"), None);
        assert_eq!(p.frame_of("fluid_data_00a1.vdb"), None);
        assert_eq!(p.frame_of("fluid_data_0001.vdb.bak"), None);
        assert_eq!(
            p.sibling("sequence", "json"),
            PathBuf::from("cache/fluid_data_sequence.json")
        );
        let q = FramePattern::parse(Path::new("out/frame_%04d.qbk"))
            .unwrap()
            .unwrap();
        assert_eq!(q.path(3), PathBuf::from("out/frame_0003.qbk"));
        let d = FramePattern::parse(Path::new("f%d.qbk")).unwrap().unwrap();
        assert_eq!(d.path(3), PathBuf::from("f3.qbk"));
        assert_eq!(d.frame_of("f10.qbk"), Some(10));
        assert_eq!(d.frame_of("f010.qbk"), None);
        assert_eq!(FramePattern::parse(Path::new("plain.vdb")).unwrap(), None);
        assert_eq!(FramePattern::parse(Path::new("100%.vdb")).unwrap(), None);
        assert!(matches!(
            FramePattern::parse(Path::new("a_##_##.vdb")),
            Err(PatternError::Several(_))
        ));
        assert!(matches!(
            FramePattern::parse(Path::new("run_##/f_##.vdb")),
            Err(PatternError::InDirectory(_))
        ));
    }

    #[test]
    fn ranges_and_gaps() {
        let fr = |frame, q: (f32, f32)| ManifestFrame {
            frame,
            input: String::new(),
            output: String::new(),
            leaf_cells: 0,
            fields: vec![FieldRange {
                name: "q".into(),
                min: q.0,
                max: q.1,
            }],
        };
        let r = global_ranges(&[fr(1, (-1.0, 2.0)), fr(2, (-3.0, 1.0))]);
        assert_eq!(
            r,
            [FieldRange {
                name: "q".into(),
                min: -3.0,
                max: 2.0
            }]
        );
        assert_eq!(gaps(&[1, 2, 5, 6]), [3, 4]);
        assert!(gaps(&[4]).is_empty());
    }

    #[test]
    fn manifest_round_trip_and_bad_manifests() {
        let dir = tempfile::tempdir().expect("tempdir");
        let pattern = FramePattern::parse(&dir.path().join("f_####.qbk"))
            .expect("pattern")
            .expect("placeholder");
        assert!(Manifest::find(&pattern).expect("none").is_none());
        let m = Manifest {
            input_pattern: "in_####.vdb".into(),
            output_pattern: "f_####.qbk".into(),
            frames: vec![],
            failed: vec![],
            missing: vec![2],
            fields: vec![FieldRange {
                name: "q".into(),
                min: -1.5,
                max: 0.25,
            }],
        };
        let path = pattern.manifest_path();
        assert_eq!(path, dir.path().join("f_sequence.json"));
        // Unknown keys are ignored (a newer baker may add some).
        let mut v: serde_json::Value = serde_json::to_value(&m).expect("json");
        v["future_key"] = serde_json::json!(1);
        std::fs::write(&path, v.to_string()).expect("write");
        let (found, back) = Manifest::find(&pattern).expect("read").expect("some");
        assert_eq!(found, path);
        assert_eq!(back.fields, m.fields);
        assert_eq!(back.missing, [2]);
        // Not JSON, and a range no colour map can use: errors naming the file.
        std::fs::write(&path, "{").expect("write");
        let e = Manifest::load(&path).expect_err("garbage");
        assert!(matches!(e.kind, ManifestErrorKind::Parse(_)), "{e}");
        assert!(
            e.to_string().starts_with(&path.display().to_string()),
            "{e}"
        );
        v["fields"][0]["min"] = serde_json::json!(3.0);
        std::fs::write(&path, v.to_string()).expect("write");
        let e = Manifest::load(&path).expect_err("range");
        assert!(matches!(e.kind, ManifestErrorKind::Range { .. }), "{e}");
    }
}
