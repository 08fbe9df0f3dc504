//! Where a mesh file goes in the scene (part of the view state), the form the command
//! line and the panel give it in, `PATH[@x,y,z,scale]`, and the checks every placement
//! passes (from a flag, a view state or the panel).

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::error::{MeshError, MeshErrorKind};

/// How a mesh file is placed in the scene (part of the view state): a vertex `v` of the
/// file ends up at `translation + scale · v`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MeshInstance {
    pub path: PathBuf,
    pub translation: [f64; 3],
    pub scale: f64,
    pub colour: [f32; 3],
}

/// Default colour of meshes given on the command line: light grey.
pub(crate) const DEFAULT_MESH_COLOUR: [f32; 3] = [0.8, 0.8, 0.8];

impl MeshInstance {
    /// A mesh at its file coordinates.
    pub fn at_origin(path: impl Into<PathBuf>) -> MeshInstance {
        MeshInstance {
            path: path.into(),
            translation: [0.0; 3],
            scale: 1.0,
            colour: DEFAULT_MESH_COLOUR,
        }
    }

    /// Parses the CLI form `PATH[@x,y,z,scale]`, e.g. `data/sphere.obj@0,0,0,1`.
    pub(crate) fn parse(spec: &str) -> Result<MeshInstance, MeshSpecError> {
        let Some((path, place)) = spec.rsplit_once('@') else {
            return Ok(MeshInstance::at_origin(spec));
        };
        let nums: Vec<f64> = place
            .split(',')
            .map(|s| s.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|error| MeshSpecError::Number {
                place: place.to_string(),
                error,
            })?;
        let [x, y, z, scale] = nums[..] else {
            return Err(MeshSpecError::Count {
                place: place.to_string(),
                found: nums.len(),
            });
        };
        let m = MeshInstance {
            translation: [x, y, z],
            scale,
            ..MeshInstance::at_origin(path)
        };
        m.validate().map_err(MeshSpecError::Placement)?;
        Ok(m)
    }

    /// Finite translation, finite positive scale, colour components in 0..=1.
    pub(crate) fn validate(&self) -> Result<(), MeshError> {
        let err = |kind| Err(MeshError::new(&self.path, kind));
        if self.translation.iter().any(|x| !x.is_finite()) {
            return err(MeshErrorKind::Translation {
                translation: self.translation,
            });
        }
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return err(MeshErrorKind::Scale { scale: self.scale });
        }
        if self.colour.iter().any(|c| !(0.0..=1.0).contains(c)) {
            return err(MeshErrorKind::Colour {
                colour: self.colour,
            });
        }
        Ok(())
    }
}

/// Why a `PATH[@x,y,z,scale]` mesh spec is refused.
#[derive(Debug, thiserror::Error)]
pub enum MeshSpecError {
    #[error("mesh placement `{place}`: expected x,y,z,scale numbers: {error}")]
    Number {
        place: String,
        error: std::num::ParseFloatError,
    },
    #[error("mesh placement `{place}`: expected 4 numbers x,y,z,scale, found {found}")]
    Count { place: String, found: usize },
    /// The numbers parse but do not place a mesh (a scale ≤ 0, …).
    #[error("{0}")]
    Placement(MeshError),
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    #[test]
    fn parse_cli_spec() {
        let m = MeshInstance::parse("data/sphere.obj@1,2,3,0.5").expect("parse");
        assert_eq!(m.path, PathBuf::from("data/sphere.obj"));
        assert_eq!(m.translation, [1.0, 2.0, 3.0]);
        assert_eq!(m.scale, 0.5);
        assert_eq!(MeshInstance::parse("a.obj").expect("plain").scale, 1.0);
        assert!(matches!(
            MeshInstance::parse("a.obj@1,2,3"),
            Err(MeshSpecError::Count { found: 3, .. })
        ));
        assert!(matches!(
            MeshInstance::parse("a.obj@1,2,3,x"),
            Err(MeshSpecError::Number { .. })
        ));
        assert!(matches!(
            MeshInstance::parse("a.obj@1,2,3,-1"),
            Err(MeshSpecError::Placement(MeshError {
                kind: MeshErrorKind::Scale { .. },
                ..
            }))
        ));
    }
}
