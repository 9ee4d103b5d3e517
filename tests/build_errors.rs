//! Mesh validation, memory limits and memory reports through the Rust API.

use rayq::mesh::MeshData;
use rayq::{
    BuildError, BuildOptions, Calibration, MemoryBudget, MeshError, Scene, Structure, TriMesh,
};

fn tri() -> MeshData {
    MeshData {
        vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![[0, 1, 2]],
    }
}

fn build(data: &MeshData, options: &BuildOptions) -> Result<Scene, BuildError> {
    Scene::build(&data.as_source(), options, Calibration::builtin())
}

const GRID: BuildOptions = BuildOptions {
    structure: Structure::Grid,
    ..BuildOptions::DEFAULT
};

#[test]
fn non_finite_vertices_are_refused_with_their_index() {
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        let mut data = tri();
        data.vertices.push([0.0, bad, 0.0]); // unused by any triangle, still refused
        assert_eq!(
            build(&data, &GRID).err(),
            Some(BuildError::InvalidMesh(MeshError::NonFiniteVertex {
                vertex: 3
            }))
        );
    }
}

#[test]
fn out_of_range_indices_are_refused_with_the_triangle() {
    let mut data = tri();
    data.indices.push([0, 1, 3]);
    assert_eq!(
        build(&data, &GRID).err(),
        Some(BuildError::InvalidMesh(MeshError::IndexOutOfRange {
            triangle: 1,
            index: 3,
            vertex_count: 3
        }))
    );
}

/// A refusal does not depend on the memory limit: validation checks the indices while it copies
/// them, so a copy the limit stops must still find the bad index (and the first bad vertex of an
/// earlier geometry before it).
#[test]
fn refusals_come_before_memory_limits() {
    let mut data = rayq::procedural::by_name("soup", 2_000).unwrap();
    let last = data.indices.len() - 1;
    data.indices[last][1] = data.vertices.len() as u32;
    let expected = MeshError::IndexOutOfRange {
        triangle: last,
        index: data.vertices.len() as u32,
        vertex_count: data.vertices.len(),
    };
    for memory_limit in [0, 1, 1_000] {
        let options = BuildOptions {
            memory_limit,
            ..GRID
        };
        assert_eq!(
            build(&data, &options).err(),
            Some(BuildError::InvalidMesh(expected))
        );
    }
    let good = tri();
    let mut bad_vertex = tri();
    bad_vertex.vertices[1][2] = f32::NAN;
    let geometries = |a: &MeshData, b: &MeshData, memory_limit| {
        let options = BuildOptions {
            memory_limit,
            ..GRID
        };
        let (a, b) = (a.as_source(), b.as_source());
        let list = vec![
            rayq::geometry::Geometry::new(&a),
            rayq::geometry::Geometry::new(&b),
        ];
        Scene::build_geometries(list, &options, Calibration::builtin(), None).err()
    };
    // (The list of geometries itself, 32 bytes, is taken before validation.)
    for memory_limit in [0, 100] {
        assert_eq!(
            geometries(&good, &data, memory_limit),
            Some(BuildError::InvalidGeometry {
                geometry: 1,
                error: expected
            })
        );
        assert_eq!(
            geometries(&bad_vertex, &data, memory_limit),
            Some(BuildError::InvalidGeometry {
                geometry: 0,
                error: MeshError::NonFiniteVertex { vertex: 1 }
            })
        );
    }
}

/// Limits below what `structure` needs stop the build with `MemoryLimit`; the smallest limit that
/// lets it through holds the finished scene.
fn memory_limit_is_enforced(structure: Structure) {
    let data = rayq::procedural::by_name("soup", 20_000).unwrap();
    let with = |memory_limit| BuildOptions {
        structure,
        memory_limit,
        ..BuildOptions::DEFAULT
    };
    let needed = build(&data, &with(0)).unwrap().report().memory_bytes;
    for limit in [1, 64, 4096, needed / 2, needed - 1] {
        assert!(
            matches!(build(&data, &with(limit)), Err(BuildError::MemoryLimit { limit: l, .. }) if l == limit),
            "{structure:?}: limit {limit} of {needed} needed was not enforced"
        );
    }
    // The peak during the build can exceed what the scene keeps, so find the smallest limit that
    // passes and check the scene then fits it.
    let fits = (0..64)
        .map(|k| needed + k * needed / 16)
        .find(|&l| build(&data, &with(l)).is_ok());
    let limit = fits.expect("a limit a few times the scene size lets the build through");
    let scene = build(&data, &with(limit)).unwrap();
    assert!(scene.report().memory_bytes <= limit);
}

#[test]
fn memory_limit_stops_the_grid_build_before_it_takes_memory() {
    memory_limit_is_enforced(Structure::Grid);
}

#[test]
fn memory_limit_stops_the_kd_tree_build_before_it_takes_memory() {
    memory_limit_is_enforced(Structure::KdTree);
}

#[test]
fn budget_accounts_every_byte_and_gives_them_back() {
    let data = rayq::procedural::by_name("sphere", 5_000).unwrap();
    let mut budget = MemoryBudget::new(0);
    let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
    let grid = rayq::UniformGrid::build(&mesh, &rayq::GridParams::DEFAULT, &mut budget).unwrap();
    assert_eq!(budget.used(), mesh.memory_bytes() + grid.memory_bytes());
    assert!(budget.peak() >= budget.used());
    grid.release(&mut budget);
    mesh.release(&mut budget);
    assert_eq!(budget.used(), 0);
    // The kd-tree's build temporaries (events, scratch) are all given back; what stays is the tree.
    let mut budget = MemoryBudget::new(0);
    let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
    let tree = rayq::KdTree::build(&mesh, &rayq::KdTreeParams::DEFAULT, &mut budget).unwrap();
    assert_eq!(budget.used(), mesh.memory_bytes() + tree.memory_bytes());
    // The root's triangle records (28 bytes each) were charged too.
    assert!(budget.peak() >= mesh.memory_bytes() + 28 * mesh.len());
    tree.release(&mut budget);
    mesh.release(&mut budget);
    assert_eq!(budget.used(), 0);
}

#[test]
fn kd_tree_bounds_straddler_references() {
    // Large overlapping triangles straddle most split planes of a deep tree.
    let data = rayq::procedural::random_soup(3_000, 5, 0.5);
    let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
    let live = (mesh.len() - mesh.degenerate_count()) as f64;
    for bound in [1.0f32, 2.0, 4.0] {
        let params = rayq::KdTreeParams {
            max_references_per_triangle: bound,
            intersection_cost: 80.0,
            ..rayq::KdTreeParams::DEFAULT
        };
        let tree = rayq::KdTree::build(&mesh, &params, &mut MemoryBudget::new(0)).unwrap();
        let per = tree.reference_count() as f64 / live;
        assert!(
            per <= f64::from(bound),
            "bound {bound}: {per} references per triangle"
        );
    }
    let unbounded = rayq::KdTreeParams {
        max_references_per_triangle: 1e6,
        intersection_cost: 80.0,
        ..rayq::KdTreeParams::DEFAULT
    };
    let tree = rayq::KdTree::build(&mesh, &unbounded, &mut MemoryBudget::new(0)).unwrap();
    assert!(
        tree.reference_count() as f64 / live > 4.0,
        "slivers should straddle enough to make the bound matter"
    );
}

#[test]
fn kd_tree_parameters_are_validated() {
    let mesh = TriMesh::from_source(&tri().as_source(), &mut MemoryBudget::new(0)).unwrap();
    let bad = [
        rayq::KdTreeParams {
            intersection_cost: f32::NAN,
            ..rayq::KdTreeParams::DEFAULT
        },
        rayq::KdTreeParams {
            traversal_cost: 0.0,
            ..rayq::KdTreeParams::DEFAULT
        },
        rayq::KdTreeParams {
            empty_bonus: 1.0,
            ..rayq::KdTreeParams::DEFAULT
        },
        rayq::KdTreeParams {
            max_references_per_triangle: 0.5,
            ..rayq::KdTreeParams::DEFAULT
        },
    ];
    for p in bad {
        assert!(
            matches!(
                rayq::KdTree::build(&mesh, &p, &mut MemoryBudget::new(0)),
                Err(BuildError::InvalidArgument { .. })
            ),
            "{p:?} was accepted"
        );
    }
}

#[test]
fn empty_mesh_is_a_scene_where_every_ray_misses() {
    let scene = build(&MeshData::default(), &GRID).unwrap();
    let ray = rayq::Ray::new(glam::Vec3::ZERO, glam::Vec3::X);
    assert!(!scene.intersect(&ray).is_hit());
    assert!(!scene.occluded(&ray));
    assert_eq!(scene.report().triangle_count, 0);
}

#[test]
fn degenerate_triangles_are_kept_counted_and_never_hit() {
    let data = MeshData {
        vertices: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        indices: vec![[0, 1, 2], [0, 0, 3], [1, 1, 1], [0, 1, 3]],
    };
    let scene = build(&data, &GRID).unwrap();
    assert_eq!(scene.mesh().degenerate_count(), 3);
    let mut rng = rayq::workload::SplitMix64::new(9);
    for _ in 0..2000 {
        let org = glam::Vec3::new(rng.next_f32() * 2.0, rng.next_f32() - 0.5, 1.0);
        let hit = scene.intersect(&rayq::Ray::new(
            org,
            glam::Vec3::new(0.0, 0.0, -1.0) + 0.1 * rng.unit_vector(),
        ));
        assert!(
            !hit.is_hit() || hit.prim == 3,
            "a degenerate triangle was hit: {hit:?}"
        );
    }
}

#[test]
fn kd_tree_builds_and_reports_its_shape() {
    let options = BuildOptions {
        structure: Structure::KdTree,
        ..BuildOptions::DEFAULT
    };
    let scene = build(&tri(), &options).expect("kd-tree builds");
    let r = scene.report();
    assert_eq!(r.structure, Structure::KdTree);
    assert_eq!(r.grid_resolution, [0; 3]);
    assert!(r.kd_node_count >= 1);
    assert_eq!(r.references_per_triangle, 1.0);
}
