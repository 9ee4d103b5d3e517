//! Every structure returns the brute-force hit, bit for bit, on every ray of every test scene.

mod common;

use common::{assert_agrees, bundled, mesh_of, reference_hits, test_rays};
use rayq::mesh::MeshData;
use rayq::procedural;
use rayq::{GridParams, KdTree, KdTreeParams, MemoryBudget, TriangleLayout, UniformGrid};

const GRIDS: [(&str, GridParams); 4] = [
    ("default", GridParams::DEFAULT),
    ("coarse", GridParams::COARSE),
    ("fine", GridParams::FINE),
    (
        "bbox-only-indexed",
        GridParams {
            density: 2.0,
            exact_overlap: false,
            layout: TriangleLayout::Indexed,
        },
    ),
];

/// kd-tree parameter sets: the default, binned splits everywhere, the exact sweep everywhere, one
/// that splits as deep as it may (tiny leaves, many straddlers), one that stops early (big leaves)
/// with the indexed layout, and one with no empty-space bonus.
const KDTREES: [(&str, KdTreeParams); 6] = [
    ("kd-default", KdTreeParams::DEFAULT),
    (
        "kd-binned",
        KdTreeParams {
            exact_below: 0,
            ..KdTreeParams::DEFAULT
        },
    ),
    (
        "kd-exact",
        KdTreeParams {
            exact_below: u32::MAX,
            ..KdTreeParams::DEFAULT
        },
    ),
    (
        "kd-deep",
        KdTreeParams {
            intersection_cost: 80.0,
            max_leaf_prims: 0,
            ..KdTreeParams::DEFAULT
        },
    ),
    (
        "kd-shallow-indexed",
        KdTreeParams {
            intersection_cost: 0.5,
            max_depth: 6,
            layout: TriangleLayout::Indexed,
            ..KdTreeParams::DEFAULT
        },
    ),
    (
        "kd-no-bonus",
        KdTreeParams {
            empty_bonus: 0.0,
            ..KdTreeParams::DEFAULT
        },
    ),
];

fn check(name: &str, data: &MeshData, side: usize, adversarial: usize) {
    let mesh = mesh_of(data);
    let rays = test_rays(
        &mesh,
        side,
        adversarial,
        0x5eed ^ data.triangle_count() as u64,
    );
    let want = reference_hits(&mesh, &rays);
    for (label, params) in GRIDS {
        let grid =
            UniformGrid::build(&mesh, &params, &mut MemoryBudget::new(0)).expect("grid builds");
        let hits = assert_agrees(&format!("{name}/{label}"), &mesh, &grid, &rays, &want);
        if !mesh.is_empty() {
            assert!(
                hits > 0,
                "{name}: no ray hit anything, the test would prove nothing"
            );
        }
    }
    for (label, params) in KDTREES {
        let tree =
            KdTree::build(&mesh, &params, &mut MemoryBudget::new(0)).expect("kd-tree builds");
        assert_agrees(&format!("{name}/{label}"), &mesh, &tree, &rays, &want);
    }
}

macro_rules! bundled_scene {
    ($test:ident, $file:literal) => {
        #[test]
        fn $test() {
            check($file, &bundled($file), 20, 1200);
        }
    };
}

bundled_scene!(teapot, "teapot");
bundled_scene!(fandisk, "fandisk");
bundled_scene!(spd_tetra, "spd_tetra");
bundled_scene!(spd_teapot, "spd_teapot");
bundled_scene!(xwing_slivers, "xwing");
bundled_scene!(f15, "f15");
bundled_scene!(stadium_teapot, "stadium_teapot");

#[test]
fn procedural_scenes() {
    for name in procedural::NAMES {
        let data = procedural::by_name(name, 1500).expect("known name");
        check(name, &data, 16, 800);
    }
}

#[test]
fn tiny_and_offset_scenes() {
    let base = procedural::closed_sphere(8);
    for (label, scale, offset) in [
        ("unit", 1.0, [0.0; 3]),
        ("tiny 1e-6", 1e-6, [0.0; 3]),
        ("offset 1e4", 1.0, [1e4, -2e4, 3e4]),
        ("huge 1e7 extent", 1e7, [0.0; 3]),
    ] {
        check(label, &base.transformed(scale, offset), 16, 800);
    }
}

#[test]
fn one_and_two_triangles_and_empty() {
    let one = MeshData {
        vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![[0, 1, 2]],
    };
    check("one triangle", &one, 8, 400);
    let two = MeshData {
        vertices: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ],
        indices: vec![[0, 1, 2], [2, 1, 3]],
    };
    check("two triangles", &two, 8, 400);
    check("empty", &MeshData::default(), 4, 16);
}

#[test]
fn duplicate_and_coplanar_triangles_tie_to_the_lowest_id() {
    let mut data = procedural::random_soup(200, 7, 0.2);
    let copy = data.clone();
    data.append(&copy);
    let mesh = mesh_of(&data);
    let rays = test_rays(&mesh, 16, 400, 3);
    let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
    let tree = KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
    let want = reference_hits(&mesh, &rays);
    let structures: [(&str, &dyn rayq::RayQuery); 2] = [("grid", &grid), ("kd-tree", &tree)];
    for (label, accel) in structures {
        assert_agrees(label, &mesh, accel, &rays, &want);
        for r in &rays {
            let h = accel.intersect(&mesh, r);
            assert!(
                !h.is_hit() || h.prim < 200,
                "{label}: a duplicate with the higher id won a tie: {h:?}"
            );
        }
    }
}

#[test]
fn axis_aligned_sheets_on_cell_boundaries() {
    // Sheets at x = k/4 inside a unit box: with 4 cells per axis they lie exactly on cell planes.
    let mut data = MeshData::default();
    for k in 0..=4 {
        let x = k as f32 / 4.0;
        data.push_quad([[x, 0.0, 0.0], [x, 1.0, 0.0], [x, 0.0, 1.0], [x, 1.0, 1.0]]);
    }
    check("sheets", &data, 16, 800);
}

#[test]
fn all_triangles_in_one_cell() {
    let mut data = procedural::random_soup(300, 11, 0.01).transformed(1e-3, [0.5, 0.5, 0.5]);
    data.append(&MeshData {
        vertices: vec![
            [-10.0, -10.0, -10.0],
            [10.0, -10.0, -10.0],
            [-10.0, 10.0, 10.0],
        ],
        indices: vec![[0, 1, 2]],
    });
    check("one cell", &data, 16, 800);
}

#[test]
fn counted_queries_return_the_same_hits_and_count_the_work() {
    let data = bundled("teapot");
    let mesh = mesh_of(&data);
    let rays = test_rays(&mesh, 16, 200, 9);
    let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
    let tree = KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
    let (mut kd_total, mut grid_total) = (0u64, 0u64);
    for r in &rays {
        let mut kw = rayq::accel::kdtree::KdWork::default();
        let h = tree.intersect_counted(&mesh, r, &mut kw);
        assert!(h.same_bits(&rayq::RayQuery::intersect(&tree, &mesh, r)));
        assert!(kw.leaves <= kw.nodes, "{kw:?}");
        assert!(!h.is_hit() || kw.tests >= 1, "a hit without a test: {kw:?}");
        let mut gw = rayq::accel::grid::GridWork::default();
        let g = grid.intersect_counted(&mesh, r, &mut gw);
        assert!(g.same_bits(&h));
        assert!(!g.is_hit() || (gw.tests >= 1 && gw.cells >= 1), "{gw:?}");
        kd_total += u64::from(kw.tests);
        grid_total += u64::from(gw.tests);
    }
    assert!(kd_total > 0 && grid_total > 0);
}

/// Triangles that shrink towards the origin by a quarter per layer on all three axes: every split
/// cuts off one layer, so a kd-tree that splits as long as it may runs down to its depth limit,
/// and rays towards and out of the origin cross every level. The walk's stack, which holds one pending subtree per level, is
/// then used to its bound (`MAX_DEPTH`): the answers must still be the brute force's (and, in a
/// debug build, the walk's stack assertions hold).
#[test]
fn trees_at_the_depth_limit_agree() {
    let mut data = MeshData::default();
    for layer in 0..220 {
        let s = 0.75f32.powi(layer);
        for a in 0..3 {
            let b = data.vertices.len() as u32;
            for k in 0..3 {
                let mut p = [0.0f32; 3];
                p[a] = s;
                p[(a + 1) % 3] = s * (0.1 + 0.05 * k as f32);
                p[(a + 2) % 3] = s * if k == 2 { 0.17 } else { 0.1 };
                data.vertices.push(p);
            }
            data.indices.push([b, b + 1, b + 2]);
        }
    }
    let mesh = mesh_of(&data);
    let mut rays = test_rays(&mesh, 16, 500, 7);
    let mut rng = rayq::workload::SplitMix64::new(3);
    for _ in 0..1500 {
        let d = glam::Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32())
            + glam::Vec3::splat(1e-3);
        rays.push(rayq::Ray::new(d * (1.0 + 2.0 * rng.next_f32()), -d));
        rays.push(rayq::Ray::new(glam::Vec3::splat(1e-30 * rng.next_f32()), d));
    }
    let want = reference_hits(&mesh, &rays);
    let deepest = KdTreeParams {
        intersection_cost: 80.0,
        max_leaf_prims: 0,
        max_depth: u32::MAX,
        ..KdTreeParams::DEFAULT
    };
    let default = KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
    let deep = KdTree::build(&mesh, &deepest, &mut MemoryBudget::new(0)).unwrap();
    assert_eq!(
        deep.depth(),
        rayq::accel::kdtree::MAX_DEPTH,
        "the scene should take the deepest tree to the depth limit"
    );
    for (name, tree) in [("kd-default", &default), ("kd-deepest", &deep)] {
        assert_agrees(name, &mesh, tree, &rays, &want);
    }
}
