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

#[test]
fn memory_limit_stops_the_build_before_it_takes_memory() {
    let data = rayq::procedural::by_name("soup", 20_000).unwrap();
    let unlimited = build(&data, &GRID).unwrap();
    let needed = unlimited.report().memory_bytes;
    for limit in [1, 64, 4096, needed / 2, needed - 1] {
        let options = BuildOptions {
            memory_limit: limit,
            ..GRID
        };
        assert!(
            matches!(build(&data, &options), Err(BuildError::MemoryLimit { limit: l, .. }) if l == limit),
            "limit {limit} of {needed} needed was not enforced"
        );
    }
    // The peak during the build can exceed what the scene keeps, so find the smallest limit that
    // passes and check the scene then fits it.
    let fits = (0..64).map(|k| needed + k * needed / 16).find(|&l| {
        build(
            &data,
            &BuildOptions {
                memory_limit: l,
                ..GRID
            },
        )
        .is_ok()
    });
    let limit = fits.expect("a limit a few times the scene size lets the build through");
    let scene = build(
        &data,
        &BuildOptions {
            memory_limit: limit,
            ..GRID
        },
    )
    .unwrap();
    assert!(scene.report().memory_bytes <= limit);
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
fn kd_tree_is_reported_unsupported_until_it_exists() {
    let options = BuildOptions {
        structure: Structure::KdTree,
        ..BuildOptions::DEFAULT
    };
    assert!(matches!(
        build(&tri(), &options),
        Err(BuildError::Unsupported { .. })
    ));
}
