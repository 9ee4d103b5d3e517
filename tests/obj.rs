//! rayq's own OBJ parser (`rayq::obj`) against `tobj`, which it replaced: on every bundled scene and
//! every scene in `../shared/scenes`, the same triangles in the same order with bit-identical vertex
//! positions, so that every figure measured on scenes loaded by `tobj` still holds; and on a file of
//! polygons, which no scene has.

use std::fs;
use std::path::{Path, PathBuf};

/// Triangle `i`'s three corners, as the bits of their coordinates.
type Corners = [[u32; 3]; 3];

fn corners(vertices: &[[f32; 3]], tri: [u32; 3]) -> Corners {
    tri.map(|v| vertices[v as usize].map(f32::to_bits))
}

/// Every triangle of `path` as `tobj` loaded it for rayq before (all objects merged, polygons fanned).
fn tobj_triangles(path: &Path) -> Vec<Corners> {
    let options = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let (models, _) =
        tobj::load_obj(path, &options).unwrap_or_else(|e| panic!("tobj: {}: {e}", path.display()));
    let mut out = Vec::new();
    for m in &models {
        let vertices: Vec<[f32; 3]> = m
            .mesh
            .positions
            .chunks_exact(3)
            .map(|p| [p[0], p[1], p[2]])
            .collect();
        for t in m.mesh.indices.chunks_exact(3) {
            out.push(corners(&vertices, [t[0], t[1], t[2]]));
        }
    }
    out
}

fn obj_files(dir: &Path) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = fs::read_dir(dir)
        .map(|entries| {
            entries
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| p.extension().is_some_and(|x| x == "obj"))
                .collect()
        })
        .unwrap_or_default();
    files.sort();
    files
}

/// Every scene file is triangles only, so this one has what they lack: quads, a hexagon, relative and
/// `v/vt/vn` indices, objects, groups and a material switch.
const POLYGONS: &str =
    "mtllib none.mtl\no a\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvn 0 0 1\n\
    f 1/1/1 2/1/1 3/1/1 4/1/1\ng b\nv 2 0 1\nv 3 0 1\nv 3.5 1 1\nv 3 2 1\nv 2 2 1\nv 1.5 1 1\n\
    usemtl red\nf -6 -5 -4 -3 -2 -1\no c\nf 1//1 3//1 5//1 7//1\nf 2 4 6\n";

#[test]
fn same_triangles_as_tobj_on_every_scene() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let polygons = Path::new(env!("CARGO_TARGET_TMPDIR")).join("polygons.obj");
    fs::write(&polygons, POLYGONS).expect("write polygons.obj");
    let mut bundled = obj_files(&root.join("scenes"));
    assert!(
        bundled.len() >= 7,
        "scenes/ has {} OBJ files",
        bundled.len()
    );
    bundled.push(polygons);
    let shared = obj_files(&root.join("../shared/scenes"));
    let mut compared = 0;
    for path in bundled.iter().chain(&shared) {
        let ours = rayq::obj::load_obj(path).unwrap_or_else(|e| panic!("{e}"));
        let theirs = tobj_triangles(path);
        assert_eq!(
            ours.indices.len(),
            theirs.len(),
            "{}: triangle count",
            path.display()
        );
        for (i, (&tri, want)) in ours.indices.iter().zip(&theirs).enumerate() {
            assert_eq!(
                &corners(&ours.vertices, tri),
                want,
                "{}: triangle {i}",
                path.display()
            );
        }
        compared += 1;
    }
    eprintln!(
        "compared {compared} files ({} in scenes/, polygons.obj, {} in ../shared/scenes)",
        bundled.len() - 1,
        shared.len()
    );
}
