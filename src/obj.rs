//! Loading OBJ files (through `tobj`) for examples, tests, benches and the C helper `rq_obj_load`.

extern crate std;

use std::path::Path;
use std::string::String;
use std::vec::Vec;

use crate::mesh::MeshData;

/// Loads every object of an OBJ file into one mesh: polygons are fanned into triangles, vertex
/// indices of later objects are offset so that the result is one indexed mesh. Normals, texture
/// coordinates and materials are ignored.
pub fn load_obj(path: impl AsRef<Path>) -> Result<MeshData, String> {
    let path = path.as_ref();
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) =
        tobj::load_obj(path, &options).map_err(|e| std::format!("{}: {e}", path.display()))?;
    let mut mesh = MeshData::default();
    for m in &models {
        let base =
            u32::try_from(mesh.vertices.len()).map_err(|_| String::from("too many vertices"))?;
        mesh.vertices
            .extend(m.mesh.positions.chunks_exact(3).map(|p| [p[0], p[1], p[2]]));
        let tris: Vec<[u32; 3]> = m
            .mesh
            .indices
            .chunks_exact(3)
            .map(|t| [base + t[0], base + t[1], base + t[2]])
            .collect();
        mesh.indices.extend(tris);
    }
    Ok(mesh)
}
