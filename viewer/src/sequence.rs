//! Rendering a frame sequence (`render 'out/frame_####.qbk' -o 'png/frame_####.png'`) with
//! one view: which frames, and what the frames share — the box the camera frames and the
//! field ranges the default iso value and colour map come from.
//!
//! The ranges are fixed for the whole sequence so that a colour means the same value in
//! every frame; per-frame ranges would make colours flicker as a field's maximum changes.
//! They come from the manifest `qbricks-bake` writes next to the frames, which holds each
//! field's range over every baked frame; without one, from the union of the rendered
//! frames' own ranges.
//!
//! The manifest is also trusted on which files are frames of the bake ([`plan`]): a frame
//! it lists as failed, or a file it does not list at all, is left over from an earlier bake
//! (the new bake failed to replace it, or never made it) and is skipped with a warning
//! rather than shown as if it belonged to the sequence.

use std::path::{Path, PathBuf};
use std::str::FromStr;

use format::sequence::{FieldRange, FramePattern, Manifest, ManifestError, PatternError};
use format::OpenOptions;

use crate::view_state::ViewState;

/// Most frames `--frames` may name (a typo like `1..1000000000` would otherwise report a
/// billion missing files): the shared frame bound.
use files::limits::MAX_FRAMES as MAX_RANGE_FRAMES;

/// `--frames`: `A..B` (both included), `A..`, `..B` or `A`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FrameRange {
    pub first: Option<u64>,
    pub last: Option<u64>,
}

/// Why a `--frames` range does not parse.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum FrameRangeError {
    #[error("expected A..B (both included), A.., ..B or A, found `{text}`")]
    Form { text: String },
    #[error("first frame {first} is after the last {last} in `{text}`")]
    Reversed { first: u64, last: u64, text: String },
}

impl FromStr for FrameRange {
    type Err = FrameRangeError;
    fn from_str(s: &str) -> Result<Self, FrameRangeError> {
        let bad = || FrameRangeError::Form {
            text: s.to_string(),
        };
        let num = |t: &str| -> Result<Option<u64>, FrameRangeError> {
            let t = t.trim();
            if t.is_empty() {
                Ok(None)
            } else {
                t.parse().map(Some).map_err(|_| bad())
            }
        };
        let (first, last) = match s.split_once("..") {
            Some((a, b)) => (num(a)?, num(b.strip_prefix('=').unwrap_or(b))?),
            None => {
                let n = num(s)?.ok_or_else(bad)?;
                (Some(n), Some(n))
            }
        };
        if let (Some(a), Some(b)) = (first, last) {
            if a > b {
                return Err(FrameRangeError::Reversed {
                    first: a,
                    last: b,
                    text: s.to_string(),
                });
            }
        }
        Ok(FrameRange { first, last })
    }
}

/// Why the frames of a sequence could not be chosen.
#[derive(Debug, thiserror::Error)]
pub enum SequenceError {
    #[error("{pattern}: cannot list {}: {error}", dir.display())]
    List {
        pattern: String,
        dir: PathBuf,
        error: std::io::Error,
    },
    #[error("{pattern}: no file matches the frame pattern{}", range_note(*range))]
    NoFrames {
        pattern: String,
        range: Option<FrameRange>,
    },
    #[error("--frames {first}..{last}: expected at most {MAX_RANGE_FRAMES} frames")]
    TooMany { first: u64, last: u64 },
    #[error("{0}")]
    Manifest(#[from] ManifestError),
    #[error(
        "{pattern}: every frame that matches is skipped (the manifest {} lists them as failed \
         or does not list them): {}",
        manifest.display(),
        skipped_list(skipped)
    )]
    AllSkipped {
        pattern: String,
        manifest: PathBuf,
        skipped: Vec<Skipped>,
    },
}

fn skipped_list(skipped: &[Skipped]) -> String {
    let mut names: Vec<String> = skipped
        .iter()
        .take(10)
        .map(|s| s.path.display().to_string())
        .collect();
    if skipped.len() > 10 {
        names.push("…".to_string());
    }
    names.join(", ")
}

/// A file that matches the pattern but is not a frame of the bake the manifest describes.
#[derive(Debug, Clone, PartialEq)]
pub struct Skipped {
    pub frame: u64,
    pub path: PathBuf,
    /// Why, in words: the bake's own error, or that the manifest does not list it.
    pub why: String,
}

impl std::fmt::Display for Skipped {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}: skipped, {}", self.path.display(), self.why)
    }
}

/// The frames of a sequence to show, what they share, and the files left out.
#[derive(Debug, Clone)]
pub struct SequencePlan {
    pub frames: Vec<(u64, PathBuf)>,
    pub skipped: Vec<Skipped>,
    pub info: SequenceInfo,
}

/// Chooses the frames ([`select_frames`]), drops those the manifest says are not frames of
/// its bake (see the module docs) and surveys the rest ([`survey`]).
pub fn plan(
    pattern: &FramePattern,
    shown: &str,
    range: Option<FrameRange>,
) -> Result<SequencePlan, SequenceError> {
    let chosen = select_frames(pattern, shown, range)?;
    let manifest = Manifest::find(pattern)?;
    let (frames, skipped) = match &manifest {
        Some((_, m)) => trust(chosen, m),
        None => (chosen, Vec::new()),
    };
    if frames.is_empty() {
        return Err(SequenceError::AllSkipped {
            pattern: shown.to_string(),
            manifest: pattern.manifest_path(),
            skipped,
        });
    }
    let info = survey_with(&frames, manifest)?;
    Ok(SequencePlan {
        frames,
        skipped,
        info,
    })
}

/// Splits `frames` into those the manifest lists as baked (or that do not exist: a frame
/// asked for by `--frames` that is missing still fails as itself) and the rest.
fn trust(frames: Vec<(u64, PathBuf)>, manifest: &Manifest) -> (Vec<(u64, PathBuf)>, Vec<Skipped>) {
    let mut kept = Vec::new();
    let mut skipped = Vec::new();
    for (frame, path) in frames {
        if let Some(f) = manifest.failed.iter().find(|f| f.frame == frame) {
            if path.exists() {
                skipped.push(Skipped {
                    frame,
                    why: format!(
                        "its bake failed ({}), so this file is from an earlier bake",
                        f.error
                    ),
                    path,
                });
                continue;
            }
        } else if !manifest.frames.iter().any(|f| f.frame == frame) && path.exists() {
            skipped.push(Skipped {
                frame,
                why: "the manifest of the bake does not list it, so it is from an earlier bake"
                    .to_string(),
                path,
            });
            continue;
        }
        kept.push((frame, path));
    }
    (kept, skipped)
}

fn range_note(r: Option<FrameRange>) -> String {
    match r {
        Some(r) => format!(
            " in --frames {}..{}",
            r.first.map_or(String::new(), |f| f.to_string()),
            r.last.map_or(String::new(), |f| f.to_string())
        ),
        None => String::new(),
    }
}

/// The frames to render, in order: without a range, the files that exist; with one, every
/// number in it (a missing file then fails as that frame, since it was asked for), an open
/// end standing for the first or last existing frame.
pub fn select_frames(
    pattern: &FramePattern,
    shown: &str,
    range: Option<FrameRange>,
) -> Result<Vec<(u64, PathBuf)>, SequenceError> {
    let existing = pattern.scan().map_err(|error| SequenceError::List {
        pattern: shown.to_string(),
        dir: pattern.dir().to_path_buf(),
        error,
    })?;
    let none = || SequenceError::NoFrames {
        pattern: shown.to_string(),
        range,
    };
    let Some(r) = range else {
        return if existing.is_empty() {
            Err(none())
        } else {
            Ok(existing)
        };
    };
    let first = match r.first {
        Some(f) => f,
        None => existing
            .iter()
            .map(|f| f.0)
            .find(|&f| r.last.is_none_or(|l| f <= l))
            .ok_or_else(none)?,
    };
    let last = match r.last {
        Some(l) => l,
        None => existing
            .iter()
            .map(|f| f.0)
            .rfind(|&f| f >= first)
            .ok_or_else(none)?,
    };
    if last - first >= MAX_RANGE_FRAMES {
        return Err(SequenceError::TooMany { first, last });
    }
    Ok((first..=last).map(|f| (f, pattern.path(f))).collect())
}

/// Where the sequence's field ranges came from (said on stderr, since it decides the
/// colours).
#[derive(Debug, Clone, PartialEq)]
pub enum RangeSource {
    /// The bake's manifest, over every frame it baked.
    Manifest(PathBuf),
    /// No manifest: the union over this many frames that could be opened.
    Frames(usize),
}

/// What the frames of a sequence share.
#[derive(Debug, Clone)]
pub struct SequenceInfo {
    /// Union of the frames' data boxes (world), `None` when no frame could be opened.
    pub bounds: Option<([f64; 3], [f64; 3])>,
    /// Per field, its range over the sequence (manifest order, then fields only the
    /// frames have).
    pub fields: Vec<FieldRange>,
    pub source: RangeSource,
    /// What each frame that opened holds on its own, in frame order: the per-frame
    /// defaults (`sequence_defaults`) compare the sequence's iso value with it.
    pub frames: Vec<FrameSummary>,
}

/// One frame's own data box (world) and field ranges, as its file's header gives them.
#[derive(Debug, Clone, PartialEq)]
pub struct FrameSummary {
    pub frame: u64,
    pub bounds: ([f64; 3], [f64; 3]),
    pub fields: Vec<FieldRange>,
}

impl SequenceInfo {
    /// The summary of `frame`, `None` when it did not open in the survey.
    pub fn frame(&self, frame: u64) -> Option<&FrameSummary> {
        self.frames.iter().find(|f| f.frame == frame)
    }
}

impl SequenceInfo {
    /// The view a sequence starts with when no state file says otherwise: the camera
    /// frames the union of the frames' boxes (the flow moves, so one frame's box or
    /// iso-surface would lose it later), iso value and colour map from the sequence's
    /// ranges. `render` then narrows the camera to the union of the frames' iso surfaces
    /// (`sequence_defaults::frame_surfaces`), which needs a pass over the cells.
    pub fn default_state(&self) -> ViewState {
        // No frame opened: every frame fails with its own error anyway.
        let (lo, hi) = self.bounds.unwrap_or(([0.0; 3], [1.0; 3]));
        ViewState::default_for(lo, hi, &self.fields)
    }
}

/// Opens every frame once, without hashing it (validation still runs; the render opens
/// it again with the checksum), for the union of the data boxes and of the field ranges;
/// takes the ranges from the manifest next to the frames when there is one. A frame that
/// does not open is left out here: its error is reported when it is rendered.
pub fn survey(
    pattern: &FramePattern,
    frames: &[(u64, PathBuf)],
) -> Result<SequenceInfo, ManifestError> {
    survey_with(frames, Manifest::find(pattern)?)
}

/// [`survey`] with the manifest already found.
fn survey_with(
    frames: &[(u64, PathBuf)],
    manifest: Option<(PathBuf, Manifest)>,
) -> Result<SequenceInfo, ManifestError> {
    let mut bounds: Option<([f64; 3], [f64; 3])> = None;
    let mut own: Vec<FieldRange> = Vec::new();
    let mut summaries = Vec::new();
    // Only the bounds and the fields are read: nothing that grows with the data.
    let options = OpenOptions {
        verify_checksum: false,
        structure: format::Structure::OnUse,
    };
    for (frame, path) in frames {
        let Ok(view) = format::BrickFileView::open_with(path, &options) else {
            continue;
        };
        let file = view.file();
        let b = format::query::bounds(file);
        summaries.push(FrameSummary {
            frame: *frame,
            bounds: (b.min, b.max),
            fields: file
                .fields
                .iter()
                .map(|f| FieldRange {
                    name: f.name.as_str().to_string(),
                    min: f.min.to_native(),
                    max: f.max.to_native(),
                })
                .collect(),
        });
        bounds = Some(match bounds {
            None => (b.min, b.max),
            Some((lo, hi)) => (
                std::array::from_fn(|a| lo[a].min(b.min[a])),
                std::array::from_fn(|a| hi[a].max(b.max[a])),
            ),
        });
        for f in file.fields.iter() {
            let (name, min, max) = (f.name.as_str(), f.min.to_native(), f.max.to_native());
            match own.iter_mut().find(|r| r.name == name) {
                Some(r) => {
                    r.min = r.min.min(min);
                    r.max = r.max.max(max);
                }
                None => own.push(FieldRange {
                    name: name.to_string(),
                    min,
                    max,
                }),
            }
        }
    }
    let (fields, source) = match manifest {
        Some((path, manifest)) => {
            let mut fields = manifest.fields;
            for f in own {
                if !fields.iter().any(|m| m.name == f.name) {
                    fields.push(f);
                }
            }
            (fields, RangeSource::Manifest(path))
        }
        None => (own, RangeSource::Frames(summaries.len())),
    };
    Ok(SequenceInfo {
        bounds,
        fields,
        source,
        frames: summaries,
    })
}

/// Output path of `frame` for an output pattern, refusing a plain output name: every frame
/// would overwrite the one before.
pub fn output_pattern(output: &Path) -> Result<FramePattern, OutputPatternError> {
    match FramePattern::parse(output) {
        Ok(Some(p)) => Ok(p),
        Ok(None) => Err(OutputPatternError::NotPattern {
            output: output.to_path_buf(),
        }),
        Err(e) => Err(OutputPatternError::Pattern(e)),
    }
}

/// Why `-o` cannot name the frames of a sequence.
#[derive(Debug, thiserror::Error)]
pub enum OutputPatternError {
    #[error(
        "{}: the input is a frame sequence, so -o must be a pattern too \
         (e.g. png/frame_####.png or png/frame_%04d.png)",
        output.display()
    )]
    NotPattern { output: PathBuf },
    #[error("{0}")]
    Pattern(PatternError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_ranges_parse() {
        let r = |a, b| FrameRange { first: a, last: b };
        assert_eq!("2..5".parse(), Ok(r(Some(2), Some(5))));
        assert_eq!("2..=5".parse(), Ok(r(Some(2), Some(5))));
        assert_eq!("7".parse(), Ok(r(Some(7), Some(7))));
        assert_eq!("3..".parse(), Ok(r(Some(3), None)));
        assert_eq!("..3".parse(), Ok(r(None, Some(3))));
        for bad in ["", "a..b", "5..2", "-1..3", "1...3", ".."] {
            let got: Result<FrameRange, _> = bad.parse();
            // `..` alone is every frame: allowed.
            if bad == ".." {
                assert_eq!(got, Ok(r(None, None)));
            } else {
                assert!(got.is_err(), "{bad}: {got:?}");
            }
        }
    }

    #[test]
    fn frames_are_chosen_from_disk_or_the_range() {
        let dir = tempfile::tempdir().expect("tempdir");
        for f in [1, 2, 4] {
            std::fs::write(dir.path().join(format!("f_{f:04}.qbk")), b"x").expect("write");
        }
        let p = FramePattern::parse(&dir.path().join("f_####.qbk"))
            .expect("pattern")
            .expect("some");
        let nums = |v: Vec<(u64, PathBuf)>| v.into_iter().map(|f| f.0).collect::<Vec<_>>();
        assert_eq!(nums(select_frames(&p, "f", None).expect("all")), [1, 2, 4]);
        let range = |s: &str| Some(s.parse::<FrameRange>().expect("range"));
        assert_eq!(
            nums(select_frames(&p, "f", range("2..4")).expect("range")),
            [2, 3, 4]
        );
        assert_eq!(
            nums(select_frames(&p, "f", range("3..")).expect("open end")),
            [3, 4]
        );
        assert_eq!(
            nums(select_frames(&p, "f", range("..2")).expect("open start")),
            [1, 2]
        );
        assert!(matches!(
            select_frames(&p, "f", range("5..")),
            Err(SequenceError::NoFrames { .. })
        ));
        assert!(matches!(
            select_frames(&p, "f", range("0..1000000")),
            Err(SequenceError::TooMany { .. })
        ));
        let empty = FramePattern::parse(&dir.path().join("g_####.qbk"))
            .expect("pattern")
            .expect("some");
        assert!(matches!(
            select_frames(&empty, "g", None),
            Err(SequenceError::NoFrames { .. })
        ));
        assert!(matches!(
            output_pattern(Path::new("out.png")),
            Err(OutputPatternError::NotPattern { .. })
        ));
        assert!(output_pattern(Path::new("png/f_%04d.png")).is_ok());
    }
}
