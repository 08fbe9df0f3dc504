//! View states as JSON files: parsed strictly (an unknown key is an error, so a typo
//! never falls back to a default), validated, written atomically.

use std::io::Write;
use std::path::{Path, PathBuf};

use files::input::{read_whole, InputErrorKind, Limits};

use super::{InvalidViewState, ViewState};

/// Why a view state could not be loaded or saved.
#[derive(Debug, thiserror::Error)]
pub enum ViewStateError {
    // The cause is part of the one-line message, not a `source` (which would print it
    // twice in an anyhow chain).
    #[error("{}: {error}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{}: not a valid view state: {error}", path.display())]
    Parse {
        path: PathBuf,
        error: serde_json::Error,
    },
    #[error("{}: {error}", path.display())]
    Invalid {
        path: PathBuf,
        error: InvalidViewState,
    },
    /// Larger than a view state may be; `size` is `None` for a stream that went on past
    /// the limit.
    #[error(
        "{}: expected a JSON view state of at most {limit} bytes, found {}",
        path.display(),
        found_bytes(*size)
    )]
    TooLarge {
        path: PathBuf,
        limit: u64,
        size: Option<u64>,
    },
    /// Not a file that can be read whole (a directory, …).
    #[error("{}: {kind}", path.display())]
    Input { path: PathBuf, kind: InputErrorKind },
    #[error("{}: not UTF-8 text: {error}", path.display())]
    NotUtf8 {
        path: PathBuf,
        error: std::str::Utf8Error,
    },
}

/// `N bytes`, or `more` for a stream read no further than the limit.
fn found_bytes(size: Option<u64>) -> String {
    match size {
        Some(n) => format!("{n} bytes"),
        None => "more".to_string(),
    }
}

impl ViewState {
    /// Parses and validates JSON text; `path` only names the source in errors.
    pub fn from_json(path: &Path, text: &str) -> Result<ViewState, ViewStateError> {
        let state: ViewState =
            serde_json::from_str(text).map_err(|error| ViewStateError::Parse {
                path: path.to_path_buf(),
                error,
            })?;
        state.validate().map_err(|error| ViewStateError::Invalid {
            path: path.to_path_buf(),
            error,
        })?;
        Ok(state)
    }

    /// Reads a state file (at most 16 MiB, a regular file checked by its size before
    /// reading, a device or pipe read no further than that).
    pub fn load(path: &Path) -> Result<ViewState, ViewStateError> {
        const MAX_BYTES: u64 = 16 << 20;
        let path_buf = || path.to_path_buf();
        let too_large = |size| ViewStateError::TooLarge {
            path: path_buf(),
            limit: MAX_BYTES,
            size,
        };
        let bytes = read_whole(path, Limits::both(MAX_BYTES)).map_err(|e| match e.kind {
            InputErrorKind::Io(error) => ViewStateError::Io {
                path: path_buf(),
                error,
            },
            InputErrorKind::TooLarge { size, .. } => too_large(Some(size)),
            InputErrorKind::StreamTooLarge { .. } => too_large(None),
            kind => ViewStateError::Input {
                path: path_buf(),
                kind,
            },
        })?;
        let text = String::from_utf8(bytes).map_err(|e| ViewStateError::NotUtf8 {
            path: path_buf(),
            error: e.utf8_error(),
        })?;
        ViewState::from_json(path, &text)
    }

    /// Pretty JSON text.
    pub fn to_json(&self) -> String {
        // Serialising plain data with string keys cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Writes the state with [`files::output::write_atomic`] (temporary file next to
    /// `path`, renamed over it; a device or FIFO is written into).
    pub fn save(&self, path: &Path) -> Result<(), ViewStateError> {
        files::output::write_atomic(path, |f| {
            f.write_all(self.to_json().as_bytes())?;
            f.write_all(b"\n")
        })
        .map_err(|error| ViewStateError::Io {
            path: path.to_path_buf(),
            error,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::Projection;
    use crate::colormap::ColorMap;
    use crate::mesh::MeshInstance;
    use crate::view_state::tests::fields;
    use crate::view_state::{Mode, Strategy};

    #[test]
    fn json_round_trip_through_a_file() {
        let dir = tempfile::tempdir().expect("tempdir");
        let path = dir.path().join("view.json");
        let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        s.mode = Mode::Dvr;
        s.strategy = Strategy::Bisect;
        s.meshes.push(MeshInstance::at_origin("data/sphere.obj"));
        s.shadows = true;
        s.seed = 42;
        s.camera.projection = Projection::Orthographic { width: 2.5 };
        s.colormap = ColorMap::seed_report();
        s.save(&path).expect("save");
        let back = ViewState::load(&path).expect("load");
        assert_eq!(s, back);
        // Only the final file is left behind.
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .expect("read_dir")
            .map(|e| e.expect("entry").file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("view.json")]);
        let text = std::fs::read_to_string(&path).expect("read");
        assert!(text.contains("\"mode\": \"dvr\""), "{text}");
        assert!(text.contains("\"strategy\": \"bisect\""), "{text}");
    }

    /// The overlays are a list of names in the JSON; a state saved before they existed
    /// (no `overlays` key) shows every overlay but the title, `[]` none, and an unknown
    /// name is refused naming the known ones.
    #[test]
    fn overlays_are_a_list_of_names() {
        use crate::overlay::Overlays;
        let mut s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        s.overlays = "legend,title".parse().expect("parse");
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        assert_eq!(v["overlays"], serde_json::json!(["legend", "title"]));
        let path = Path::new("v.json");
        assert_eq!(ViewState::from_json(path, &v.to_string()).expect("back"), s);
        v["overlays"] = serde_json::json!([]);
        let none = ViewState::from_json(path, &v.to_string()).expect("none");
        assert_eq!(none.overlays, Overlays::NONE);
        v.as_object_mut().expect("object").remove("overlays");
        let old = ViewState::from_json(path, &v.to_string()).expect("old state");
        assert_eq!(old.overlays, Overlays::default());
        v["overlays"] = serde_json::json!(["grid"]);
        let e = ViewState::from_json(path, &v.to_string()).expect_err("unknown");
        assert!(
            e.to_string().contains("grid") && e.to_string().contains("legend"),
            "{e}"
        );
    }

    #[test]
    fn unknown_fields_are_rejected_with_their_name() {
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["isovalue"] = serde_json::json!(0.1);
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("unknown");
        let msg = e.to_string();
        assert!(
            msg.starts_with("v.json: ") && msg.contains("isovalue"),
            "{msg}"
        );
        // The cause is in the message only once (an anyhow chain would repeat a source).
        assert!(std::error::Error::source(&e).is_none());
        // Nested: inside the camera and inside a light.
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["camera"]["fov"] = serde_json::json!(30);
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("nested");
        assert!(e.to_string().contains("fov"), "{e}");
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["lights"][0]["power"] = serde_json::json!(3);
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("light");
        assert!(e.to_string().contains("power"), "{e}");
        // Bad enum strings.
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        v["strategy"] = serde_json::json!("fast");
        let e = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect_err("enum");
        assert!(e.to_string().contains("fast"), "{e}");
    }

    #[test]
    fn defaulted_fields_may_be_omitted() {
        let s = ViewState::default_for([0.0; 3], [1.0; 3], &fields());
        let mut v: serde_json::Value = serde_json::from_str(&s.to_json()).expect("json");
        let obj = v.as_object_mut().expect("object");
        for k in ["spp", "seed", "material", "meshes", "shadows", "background"] {
            obj.remove(k);
        }
        let back = ViewState::from_json(Path::new("v.json"), &v.to_string()).expect("parse");
        // A state without `material` reads the coefficients states had before issue 26
        // (so old files render as before), not the brighter ones of new views.
        let mut want = s;
        want.material = crate::shading::Material::default();
        assert_ne!(want.material, crate::shading::Material::new_view());
        assert_eq!(back, want);
    }
}
