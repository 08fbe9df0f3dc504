//! Why a mesh is refused: the file, and what is wrong with it.

use std::path::PathBuf;

use files::input::InputErrorKind;
use glam::DVec3;

/// A mesh that cannot be placed or loaded: the file and what is wrong with it.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct MeshError {
    pub path: PathBuf,
    pub kind: MeshErrorKind,
}

impl MeshError {
    pub(crate) fn new(path: impl Into<PathBuf>, kind: MeshErrorKind) -> Self {
        Self {
            path: path.into(),
            kind,
        }
    }
}

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshErrorKind {
    #[error("translation: not finite ({translation:?})")]
    Translation { translation: [f64; 3] },
    #[error("scale: expected a finite number > 0, found {scale}")]
    Scale { scale: f64 },
    #[error("colour: expected components in 0..=1, found {colour:?}")]
    Colour { colour: [f32; 3] },
    #[error("is a directory, expected an OBJ file")]
    IsDirectory,
    #[error("cannot read OBJ file: {0}")]
    Read(std::io::Error),
    /// Reading the file whole failed otherwise (a device, over the size limit...).
    #[error("{0}")]
    Input(InputErrorKind),
    #[error("not a valid OBJ file: {0}")]
    NotObj(tobj::LoadError),
    /// Vertex numbers are 1-based, as in the file.
    #[error("object `{object}`: vertex {vertex} is not finite ({:?})", DVec3::from_array(*.position))]
    VertexNotFinite {
        object: String,
        vertex: usize,
        position: [f64; 3],
    },
    /// Face and vertex numbers are 1-based, as in the file.
    #[error("object `{object}`: face {face} refers to vertex {vertex}, but there are {vertices} vertices")]
    VertexOutOfRange {
        object: String,
        face: usize,
        vertex: u64,
        vertices: usize,
    },
    #[error("expected at least one triangle, found none")]
    NoTriangles,
}
