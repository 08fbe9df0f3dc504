//! Spheres as triangle meshes, for tests, examples and benchmarks.

use glam::{DVec3, Vec3};

use super::placement::DEFAULT_MESH_COLOUR;
use super::triangles::TriangleMesh;

/// A sphere of `radius` around `centre` from a subdivided icosahedron
/// (`20·4^subdivisions` triangles, counter-clockwise seen from outside), with exact
/// radial normals.
pub fn icosphere(centre: DVec3, radius: f64, subdivisions: u32) -> TriangleMesh {
    let g = (1.0 + 5f64.sqrt()) / 2.0;
    let mut unit: Vec<DVec3> = [
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ]
    .iter()
    .map(|p| DVec3::from_array(*p).normalize())
    .collect();
    let mut tris: Vec<[u32; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..subdivisions {
        let mut cache: std::collections::HashMap<(u32, u32), u32> = Default::default();
        let mut mid = |a: u32, b: u32, unit: &mut Vec<DVec3>| -> u32 {
            let key = (a.min(b), a.max(b));
            *cache.entry(key).or_insert_with(|| {
                let p = (unit[a as usize] + unit[b as usize]).normalize();
                unit.push(p);
                (unit.len() - 1) as u32
            })
        };
        let mut next = Vec::with_capacity(tris.len() * 4);
        for [a, b, c] in tris {
            let ab = mid(a, b, &mut unit);
            let bc = mid(b, c, &mut unit);
            let ca = mid(c, a, &mut unit);
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        tris = next;
    }
    TriangleMesh {
        positions: unit.iter().map(|u| centre + radius * *u).collect(),
        triangles: tris,
        normals: Some(unit),
        colour: Vec3::from_array(DEFAULT_MESH_COLOUR),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn icosphere_is_closed_and_round() {
        let s = icosphere(DVec3::new(1.0, 2.0, 3.0), 0.5, 3);
        assert_eq!(s.triangles.len(), 20 * 64);
        assert_eq!(s.positions.len(), 10 * 64 + 2);
        for p in &s.positions {
            assert!(((*p - DVec3::new(1.0, 2.0, 3.0)).length() - 0.5).abs() < 1e-12);
        }
        // Closed, consistently oriented: each directed edge appears once, its reverse once.
        let mut edges = std::collections::HashMap::new();
        for t in &s.triangles {
            for k in 0..3 {
                *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &n) in &edges {
            assert_eq!(n, 1);
            assert_eq!(edges.get(&(b, a)), Some(&1));
        }
        // Outward winding.
        let c = DVec3::new(1.0, 2.0, 3.0);
        for t in &s.triangles {
            let [a, b, d] = t.map(|i| s.positions[i as usize]);
            assert!((b - a).cross(d - a).dot(a - c) > 0.0);
        }
    }
}
