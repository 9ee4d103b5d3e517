//! Scenes and rays at the ends of f32's range, where a fuzzing helper (stop 32) found the grid and
//! the kd-tree missing hits brute force finds: a direction whose largest component is subnormal,
//! cells narrower than 2^-128, a split plane far closer to zero than a triangle's vertices, and a
//! small triangle in a scene spanning 1e38. Each reproducer is kept as it was found (exact bit
//! patterns), beside a small family of its kind.

mod common;

use common::{assert_agrees, mesh_of, reference_hits};
use glam::Vec3;
use rayq::mesh::MeshData;
use rayq::workload::SplitMix64;
use rayq::{GridParams, KdTree, KdTreeParams, MemoryBudget, Ray, RayQuery, UniformGrid};

fn f(b: u32) -> f32 {
    f32::from_bits(b)
}

fn v(b: [u32; 3]) -> [f32; 3] {
    b.map(f)
}

/// A mesh of separate triangles given by their corners' bit patterns.
fn triangles(tris: &[[[u32; 3]; 3]]) -> MeshData {
    MeshData {
        vertices: tris.iter().flat_map(|t| t.map(v)).collect(),
        indices: (0..tris.len() as u32)
            .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
            .collect(),
    }
}

/// Every structure in `structures` gives brute force's answer on every ray; returns the hits.
fn agree(name: &str, data: &MeshData, structures: &[(&str, &dyn RayQuery)], rays: &[Ray]) -> usize {
    let mesh = mesh_of(data);
    let want = reference_hits(&mesh, rays);
    let mut hits = 0;
    for (what, s) in structures {
        hits = assert_agrees(&format!("{name}/{what}"), &mesh, *s, rays, &want);
    }
    hits
}

fn grid(data: &MeshData, params: &GridParams) -> UniformGrid {
    UniformGrid::build(&mesh_of(data), params, &mut MemoryBudget::new(0)).unwrap()
}

fn kd(data: &MeshData, params: &KdTreeParams) -> KdTree {
    KdTree::build(&mesh_of(data), params, &mut MemoryBudget::new(0)).unwrap()
}

/// A unit-sized soup of `n` small triangles.
fn soup(n: usize, seed: u64) -> MeshData {
    let mut rng = SplitMix64::new(seed);
    let mut data = MeshData::default();
    for i in 0..n as u32 {
        let p = rng.next_vec3();
        for _ in 0..3 {
            data.vertices
                .push((p + (rng.next_vec3() - 0.5) * 0.2).to_array());
        }
        data.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
    }
    data
}

/// Rays through points of `data`'s triangles from `reach` away, their directions that offset times
/// `scale` (so a hit's t is about `1/scale`).
fn rays_scaled(data: &MeshData, n: usize, reach: f32, scale: f32, seed: u64) -> Vec<Ray> {
    let mut rng = SplitMix64::new(seed);
    (0..n)
        .map(|_| {
            let idx = data.indices[(rng.next_u64() % data.indices.len() as u64) as usize];
            let [a, b, c] = idx.map(|i| Vec3::from(data.vertices[i as usize]));
            let (u, w) = (rng.next_f32() * 0.5, rng.next_f32() * 0.5);
            let target = a + (b - a) * u + (c - a) * w;
            let org = target + rng.unit_vector() * reach;
            Ray::new(org, (target - org) * scale)
        })
        .collect()
}

/// Directions whose largest component is subnormal, through a grid of many cells: the walk takes
/// such rays on the direction scaled into [1, 2). (Its scale was counted from 2^-126 instead of
/// from the component's leading bit; with cells of at least 2^-100 that no longer reaches a wrong
/// answer through the public API, and the unit test in src/accel/grid/walk.rs guards the scaling
/// itself. This family stays as a check of the path.)
#[test]
fn subnormal_directions_agree() {
    let data = soup(300, 5);
    let g = grid(&data, &GridParams::DEFAULT);
    assert!(g.resolution().iter().all(|&r| r > 1));
    let t = kd(&data, &KdTreeParams::DEFAULT);
    // Offsets of 2^-20 times these: largest components from about 2^-127 down to 2^-140.
    for (k, scale) in [
        2f32.powi(-107),
        2f32.powi(-112),
        2f32.powi(-116),
        2f32.powi(-120),
    ]
    .into_iter()
    .enumerate()
    {
        let rays = rays_scaled(&data, 400, 2f32.powi(-20), scale, 17 + k as u64);
        assert!(rays
            .iter()
            .all(|r| r.dir.abs().max_element() < f32::MIN_POSITIVE));
        let hits = agree(
            &format!("soup, directions ×{scale:e}"),
            &data,
            &[("grid", &g), ("kd-tree", &t)],
            &rays,
        );
        assert!(hits > 50, "{hits}");
    }
}

/// The reproducer as found: subnormal triangles, density 1, and a subnormal direction.
#[test]
fn subnormal_scene_and_direction_as_found() {
    let data = triangles(&[
        [
            [0x00000040, 0x00004400, 0x80000058],
            [0x80000100, 0x80010000, 0x0000001d],
            [0x00064000, 0x80058000, 0x8000006e],
        ],
        [
            [0x00015800, 0x00000740, 0x80000310],
            [0x8000c000, 0x00000031, 0x00000940],
            [0x00170000, 0x80001480, 0x00000900],
        ],
        [
            [0x80000b00, 0x00000100, 0x8000e000],
            [0x00001900, 0x00002700, 0x80000a40],
            [0x80000900, 0x00003000, 0x80128000],
        ],
        [
            [0x00005a00, 0x00007400, 0x000000c8],
            [0x801d8000, 0x80000010, 0x80000034],
            [0x80000400, 0x80000048, 0x00000018],
        ],
        [
            [0x000000d8, 0x80002000, 0x80040000],
            [0x80040000, 0x001c0000, 0x800002a0],
            [0x00000039, 0x00000030, 0x00000074],
        ],
        [
            [0x00011000, 0x00000320, 0x00180000],
            [0x00001000, 0x800c8000, 0x00000d00],
            [0x00000018, 0x00038000, 0x00000260],
        ],
    ]);
    let ray = Ray::new(
        Vec3::from(v([0x000ea925, 0x00039b61, 0x000a32f7])),
        Vec3::from(v([0x800e6525, 0x80039b2b, 0x800a33e7])),
    );
    let params = GridParams {
        density: 1.0,
        ..GridParams::DEFAULT
    };
    let (g, t) = (grid(&data, &params), kd(&data, &KdTreeParams::DEFAULT));
    let hits = agree(
        "subnormal scene",
        &data,
        &[("grid", &g), ("kd-tree", &t)],
        &[ray],
    );
    assert_eq!(hits, 1);
}

/// Scenes far narrower than 2^-100 at high densities: the grid's cells would be narrower than
/// 2^-128, whose inverse overflows f32 (every triangle was listed in the last cell only). The
/// grid now makes no cell narrower than 2^-100.
#[test]
fn scenes_of_subnormal_size_agree() {
    let s = 1e-37f32;
    let one = MeshData {
        vertices: vec![[s, 0.0, 0.0], [0.0, s, 0.0], [0.0, 0.0, s]],
        indices: vec![[0, 1, 2]],
    };
    let ray = Ray::new(Vec3::ZERO, Vec3::new(0.8, 0.1, 0.1));
    for density in [1.0, 1e3, 1e5] {
        let g = grid(
            &one,
            &GridParams {
                density,
                ..GridParams::DEFAULT
            },
        );
        assert_eq!(agree("1e-37 triangle", &one, &[("grid", &g)], &[ray]), 1);
    }
    let small = soup(200, 9).transformed(1e-36, [0.0, 0.0, 0.0]);
    let rays = rays_scaled(&small, 300, 1e-37, 1.0, 23);
    for density in [0.5, 64.0] {
        let g = grid(
            &small,
            &GridParams {
                density,
                ..GridParams::DEFAULT
            },
        );
        let t = kd(&small, &KdTreeParams::DEFAULT);
        let hits = agree(
            "soup 1e-36 across",
            &small,
            &[("grid", &g), ("kd-tree", &t)],
            &rays,
        );
        assert!(hits > 50, "{hits}");
    }
}

/// A unit triangle beside detail 1e-20 across: the kd-tree splits the triangle at planes near 0,
/// and the f64 crossing of an edge with such a plane is off by far more than the crossing itself;
/// its part's bounds lost a sliver until the crossing was widened by its error bound.
#[test]
fn split_planes_far_closer_to_zero_than_the_vertices_agree() {
    let data = triangles(&[
        [
            [0xbf800000, 0xbf800000, 0xbf000000],
            [0x3f800000, 0xbf800000, 0xbf000000],
            [0x00000000, 0x3f800000, 0x3f000000],
        ],
        [
            [0x9d8ad782, 0x9db38d46, 0x1d509a8a],
            [0x1cc83618, 0x9db38d46, 0x1d509a8a],
            [0x9d8ad782, 0x1b957c20, 0x1d509a8a],
        ],
        [
            [0x1adf1e7f, 0x9dfcf92e, 0x1c9cf8cd],
            [0x1dc06182, 0x9dfcf92e, 0x1c9cf8cd],
            [0x1adf1e7f, 0x9d00284c, 0x1c9cf8cd],
        ],
        [
            [0x9e16ebde, 0x1dd38c66, 0x9d71126f],
            [0x9d61e568, 0x1dd38c66, 0x9d71126f],
            [0x9e16ebde, 0x1e4838b7, 0x9d71126f],
        ],
        [
            [0x1e2cbbef, 0x9dfe0216, 0x9db9b3ab],
            [0x1e85973a, 0x9dfe0216, 0x9db9b3ab],
            [0x1e2cbbef, 0x9d023a1c, 0x9db9b3ab],
        ],
        [
            [0x1e1b8937, 0x1e31fc9c, 0x1e2abeb6],
            [0x1e79fbbb, 0x1e31fc9c, 0x1e2abeb6],
            [0x1e1b8937, 0x1e883790, 0x1e2abeb6],
        ],
        [
            [0x9dc03a67, 0x1d263cde, 0x1e1b2b46],
            [0x9ad557c0, 0x1d263cde, 0x1e1b2b46],
            [0x9dc03a67, 0x1e0801bc, 0x1e1b2b46],
        ],
        [
            [0x1da4fd24, 0x1dd9bef2, 0x9df3b356],
            [0x1e30f116, 0x1dd9bef2, 0x9df3b356],
            [0x1da4fd24, 0x1e4b51fd, 0x9df3b356],
        ],
        [
            [0x9e19d547, 0x9ca8c252, 0x9e396fdc],
            [0x9d6d8b0c, 0x9ca8c252, 0x9e396fdc],
            [0x9e19d547, 0x1d92b474, 0x9e396fdc],
        ],
        [
            [0x1e2c3b24, 0x1de150a6, 0x1d462c89],
            [0x1e8556d4, 0x1de150a6, 0x1d462c89],
            [0x1e2c3b24, 0x1e4f1ad7, 0x1d462c89],
        ],
    ]);
    let found = Ray::new(
        Vec3::from(v([0x1da783e3, 0x9dc14a8c, 0x1f1d76c4])),
        Vec3::from(v([0x1db77c99, 0x1e5efd36, 0x9f0dabc6])),
    );
    // The same kind of ray through many points of the unit triangle near the detail.
    let size = 1e-20f32;
    let mut rng = SplitMix64::new(31);
    let mut rays = vec![found];
    for _ in 0..600 {
        let (x, y) = (rng.next_f32() * 2.0 - 1.0, rng.next_f32() * 2.0 - 1.0);
        let target = Vec3::new(x, y, y * 0.5) * size;
        let off = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 1.0);
        rays.push(Ray::new(target + off * size * 3.0, -off * size * 3.0));
    }
    let deep = KdTreeParams {
        intersection_cost: 80.0,
        max_leaf_prims: 0,
        exact_below: u32::MAX,
        ..KdTreeParams::DEFAULT
    };
    let (a, b) = (kd(&data, &deep), kd(&data, &KdTreeParams::DEFAULT));
    let g = grid(&data, &GridParams::DEFAULT);
    let hits = agree(
        "unit triangle and 1e-20 detail",
        &data,
        &[("kd-tree, deep", &a), ("kd-tree", &b), ("grid", &g)],
        &rays,
    );
    assert!(hits > 300, "{hits}");
}

/// A triangle 0.4 across at the origin between two triangles near ±1e38, with exact overlap.
#[test]
fn a_small_triangle_in_a_scene_spanning_1e38_agrees() {
    let data = triangles(&[
        [
            [0xfe93ac6b, 0xfd4844fa, 0xfe15b342],
            [0xfed7f498, 0xfcd0c69e, 0xfdf2c4e6],
            [0xfe8ed5c9, 0x7c1e1c3c, 0xfdef33e8],
        ],
        [
            [0x7d47477d, 0x7d54fe4c, 0x7d8893ac],
            [0x7d70a0f6, 0xf9a625c0, 0x7e7a5382],
            [0x7e51acd2, 0xfb800b96, 0x7e0347c9],
        ],
        [
            [0xbe39a07e, 0xbebdc8b3, 0xbc8dd480],
            [0xbccba150, 0x3d9ae122, 0x3d3829e8],
            [0x3df01b01, 0xbdd70d23, 0xbd9ec106],
        ],
    ]);
    let org = Vec3::from(v([0xfec16a3f, 0x7d8f6360, 0xfefab393])) * 0.5;
    let mut rays = vec![Ray::new(org, -org)];
    let mut rng = SplitMix64::new(41);
    for _ in 0..300 {
        let target = (rng.next_vec3() - 0.5) * 0.3;
        let o = rng.unit_vector() * 1e38;
        rays.push(Ray::new(o, target - o));
    }
    for density in [1.0, 4.0, 64.0] {
        let g = grid(
            &data,
            &GridParams {
                density,
                ..GridParams::DEFAULT
            },
        );
        // Its f32 formula overflowed here (+∞, or NaN where 2A overflowed too).
        assert!(g.near_reach().is_finite(), "{}", g.near_reach());
        agree(
            &format!("1e38 scene at density {density}"),
            &data,
            &[("grid", &g)],
            &rays,
        );
    }
    let t = kd(&data, &KdTreeParams::DEFAULT);
    assert!(agree("1e38 scene", &data, &[("kd-tree", &t)], &rays) > 0);
    // A scene spanning ±1.7e38, whose 2A alone overflows f32.
    let wide = data.transformed(1.2, [0.0, 0.0, 0.0]);
    let g = grid(&wide, &GridParams::DEFAULT);
    assert!(g.near_reach().is_finite(), "{}", g.near_reach());
    let rays: Vec<Ray> = rays.iter().map(|r| Ray::new(r.org, r.dir * 1.2)).collect();
    let t = kd(&wide, &KdTreeParams::DEFAULT);
    agree(
        "±1.7e38 scene",
        &wide,
        &[("grid", &g), ("kd-tree", &t)],
        &rays,
    );
}

/// Triangles near f32's top, rays from so far the other way that `box − origin` overflows f32
/// though every coordinate and every hit's t is finite: on all three axes with a finite and an
/// infinite `tmax`, on one axis, and with the hits behind the origin (`tmin = −∞`). The kd-tree
/// lost most of these hits (its box entry came out +∞, or its exit −∞) until its clip left such
/// axes unconstrained (a review's finding); the grid walks them from its box's entry point.
#[test]
fn origins_whose_distance_to_the_box_overflows_agree() {
    // 200 triangles of about 2·10³⁷ around points `at(r)`, r uniform in the unit cube.
    let scene = |seed: u64, at: &dyn Fn(Vec3) -> Vec3| {
        let mut rng = SplitMix64::new(seed);
        let mut data = MeshData::default();
        for i in 0..200u32 {
            let p = at(rng.next_vec3());
            for _ in 0..3 {
                data.vertices
                    .push((p + (rng.next_vec3() - 0.5) * 2.0e37).to_array());
            }
            data.indices.push([3 * i, 3 * i + 1, 3 * i + 2]);
        }
        data
    };
    // Rays from `org` towards (or, with `behind`, away from) points `at(r)`, the direction scaled
    // so that t is about 10³⁸; the difference is taken in f64, where it does not overflow.
    let rays = |seed: u64, at: &dyn Fn(Vec3) -> Vec3, org: Vec3, behind: bool| {
        let mut rng = SplitMix64::new(seed);
        (0..600)
            .map(|k| {
                let d = (at(rng.next_vec3()).as_dvec3() - org.as_dvec3()) / 1.0e38;
                let d = if behind { -d } else { d }.as_vec3();
                match (behind, k % 2) {
                    (true, _) => Ray::segment(org, d, f32::NEG_INFINITY, f32::INFINITY),
                    (false, 0) => Ray::new(org, d),
                    (false, _) => Ray::segment(org, d, 0.0, 3.0e38),
                }
            })
            .collect::<Vec<_>>()
    };
    let all_axes = |r: Vec3| Vec3::splat(1.0e38) + r * 2.0e38;
    let one_axis = |r: Vec3| {
        Vec3::new(
            1.0e38 + r.x * 2.0e38,
            (r.y - 0.5) * 2.0e38,
            (r.z - 0.5) * 2.0e38,
        )
    };
    let behind = |r: Vec3| {
        Vec3::new(
            -1.0e38 - r.x * 2.0e38,
            (r.y - 0.5) * 2.0e38,
            (r.z - 0.5) * 2.0e38,
        )
    };
    // A case's name, where its triangles are, the rays' origin, and whether the hits are behind it.
    type Case<'a> = (&'a str, &'a dyn Fn(Vec3) -> Vec3, Vec3, bool);
    let cases: [Case; 3] = [
        ("all axes", &all_axes, Vec3::splat(-3.4e38), false),
        ("one axis", &one_axis, Vec3::new(-3.4e38, 0.0, 0.0), false),
        ("behind", &behind, Vec3::new(3.4e38, 0.0, 0.0), true),
    ];
    for (k, (name, at, org, back)) in cases.into_iter().enumerate() {
        let data = scene(7 + k as u64, at);
        let (g, t) = (
            grid(&data, &GridParams::DEFAULT),
            kd(&data, &KdTreeParams::DEFAULT),
        );
        let rays = rays(70 + k as u64, at, org, back);
        let hits = agree(name, &data, &[("grid", &g), ("kd-tree", &t)], &rays);
        assert!(hits > 30, "{name}: only {hits} of {} rays hit", rays.len());
    }
}

/// A face of area ~1 whose corners span sixty binary orders of magnitude (2^30 and 2^-30): its
/// edge cross product rounds to zero in f64, and the mesh flagged it degenerate, so no structure
/// tested it and a ray from inside the closed tetrahedron left through it (a review's finding).
/// Zero is now confirmed exactly before a triangle is flagged.
#[test]
fn a_face_whose_f64_cross_product_rounds_to_zero_is_hit() {
    let (big, tiny) = (2f32.powi(30), 2f32.powi(-30));
    let data = MeshData {
        vertices: vec![
            [0.0, big, big],
            [0.0, tiny, 0.0],
            [0.0, 0.0, tiny],
            [1.0, 0.0, 0.0],
        ],
        indices: vec![[0, 1, 2], [0, 1, 3], [1, 2, 3], [2, 0, 3]],
    };
    let mesh = mesh_of(&data);
    assert!(!mesh.is_degenerate(0));
    let ray = Ray::new(Vec3::new(0.5, 1.0, 1.0), Vec3::new(-1.0, 0.0, 0.0));
    let (g, t) = (
        grid(&data, &GridParams::DEFAULT),
        kd(&data, &KdTreeParams::DEFAULT),
    );
    let hits = agree("cross", &data, &[("grid", &g), ("kd-tree", &t)], &[ray]);
    assert_eq!(hits, 1);
}
