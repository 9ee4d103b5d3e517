//! Unit tests of the grid: the voxelization against a cell-by-cell separating-axis test, and rays
//! whose direction used to break the walk.

use alloc::vec::Vec;
use glam::Vec3;

use super::voxel::Cells;
use super::*;
use crate::accel::brute::BruteForce;
use crate::mesh::MeshData;
use crate::procedural;

fn agree(mesh: &TriMesh, grid: &UniformGrid, ray: &Ray) {
    let want = BruteForce::new(mesh).intersect(mesh, ray);
    let got = grid.intersect(mesh, ray);
    assert!(
        got.same_bits(&want),
        "{ray:?}: grid {got:?}, brute force {want:?}"
    );
    assert_eq!(grid.occluded(mesh, ray), want.is_hit(), "{ray:?}");
}

/// Whether the triangle meets the box `[lo, hi]`, by the 13 separating axes in f64 in world units
/// (a formulation independent of the voxelization's).
fn sat_overlaps(tri: &[Vec3; 3], lo: [f64; 3], hi: [f64; 3]) -> bool {
    let c = [0, 1, 2].map(|a| 0.5 * (lo[a] + hi[a]));
    let h = [0, 1, 2].map(|a| 0.5 * (hi[a] - lo[a]));
    let v = tri.map(|p| [0, 1, 2].map(|a| f64::from(p[a]) - c[a]));
    let e = [0, 1, 2].map(|i| [0, 1, 2].map(|a| v[(i + 1) % 3][a] - v[i][a]));
    let cross = |u: [f64; 3], w: [f64; 3]| {
        [
            u[1] * w[2] - u[2] * w[1],
            u[2] * w[0] - u[0] * w[2],
            u[0] * w[1] - u[1] * w[0],
        ]
    };
    let mut axes = Vec::new();
    for a in 0..3 {
        let mut unit = [0.0; 3];
        unit[a] = 1.0;
        axes.push(unit);
        for edge in e {
            axes.push(cross(unit, edge));
        }
    }
    axes.push(cross(e[0], e[1]));
    axes.iter().all(|n| {
        let p = v.map(|q| n[0] * q[0] + n[1] * q[1] + n[2] * q[2]);
        let r = n[0].abs() * h[0] + n[1].abs() * h[1] + n[2].abs() * h[2];
        let (min, max) = (p[0].min(p[1]).min(p[2]), p[0].max(p[1]).max(p[2]));
        !(min > r || max < -r)
    })
}

/// The voxelization lists a triangle in every cell whose box enlarged by the margin it meets (by
/// the separating-axis oracle), and in no cell it misses by more than the rounding slack (1/512 of
/// a cell): needles (nearly collinear, so computed normals are inexact), slivers across the box
/// (plain, tiny, far from the origin), hair, a soup, the stadium, sheets on cell planes and big
/// triangles, on grids of several densities. It also checks that
/// the work stays near the cells kept: this is what makes long triangles cheap.
#[test]
fn voxelization_lists_exactly_the_overlapped_cells() {
    let mut sheets = MeshData::default();
    for k in 0..=8 {
        let x = k as f32 / 8.0;
        sheets.push_quad([[x, 0.0, 0.0], [x, 1.0, 0.3], [0.2, x, 1.0], [1.0, 1.0, x]]);
        sheets.push_quad([[x, 0.0, 0.0], [x, 1.0, 0.0], [x, 0.0, 1.0], [x, 1.0, 1.0]]);
    }
    // Needles: nearly collinear triangles (the third vertex off the edge by ~1e-6 of its
    // length), whose computed normals are far from exact, short and long, at all angles.
    let mut needles = MeshData::default();
    let mut rng = crate::workload::SplitMix64::new(0x5eed);
    for k in 0..1500 {
        let a = rng.next_vec3();
        let len = if k % 3 == 0 { 0.5 } else { 0.05 };
        let b = a + (rng.next_vec3() - Vec3::splat(0.5)) * len;
        let c = a.lerp(b, rng.next_f32()) + (rng.next_vec3() - Vec3::splat(0.5)) * (1e-6 * len);
        let base = needles.vertices.len() as u32;
        needles.vertices.extend([a, b, c].map(|v| v.to_array()));
        needles.indices.push([base, base + 1, base + 2]);
    }
    let scenes = [
        needles,
        procedural::random_slivers(1500, 5),
        procedural::random_slivers(300, 6).transformed(1e-6, [0.0; 3]),
        procedural::random_slivers(300, 7).transformed(1.0, [1e7, -1e7, 3e6]),
        procedural::hair(150, 4, 3),
        procedural::random_soup(400, 8, 0.7),
        procedural::teapot_in_stadium(200, 400),
        sheets,
    ];
    let dense = GridParams {
        density: 8.0,
        ..GridParams::DEFAULT
    };
    let params = [
        GridParams::DEFAULT,
        GridParams::FINE,
        GridParams::COARSE,
        dense,
    ];
    let mut long = 0usize;
    for (s, data) in scenes.iter().enumerate() {
        for p in &params {
            let mut budget = MemoryBudget::new(0);
            let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
            let grid = UniformGrid::build(&mesh, p, &mut budget).unwrap();
            let shape = &grid.shape;
            let cells = Cells::new(shape);
            let res = shape.res;
            let plane = |a: usize, k: u32| {
                f64::from(shape.bounds.min[a]) + f64::from(k) * f64::from(shape.cell_size[a])
            };
            for tri in mesh.triangles() {
                let mut got = Vec::new();
                cells.for_each(tri, true, &mut |c| got.push(c as usize));
                let sorted = {
                    let mut g = got.clone();
                    g.sort_unstable();
                    g.dedup();
                    g
                };
                assert_eq!(sorted.len(), got.len(), "scene {s}: a cell twice");
                // Every cell within two of the bounds, against the oracle at the margin (must be
                // listed) and at the margin plus the slack (may be listed).
                let b = Aabb::of_triangle(tri);
                let range = |a: usize| {
                    let f = |x: f32| {
                        ((f64::from(x) - f64::from(shape.bounds.min[a]))
                            / f64::from(shape.cell_size[a]))
                        .max(0.0) as u32
                    };
                    (
                        f(b.min[a]).saturating_sub(2),
                        (f(b.max[a]) + 2).min(res[a] - 1),
                    )
                };
                let (rx, ry, rz) = (range(0), range(1), range(2));
                let mut want = 0usize;
                for z in rz.0..=rz.1 {
                    for y in ry.0..=ry.1 {
                        for x in rx.0..=rx.1 {
                            let c = [x, y, z];
                            let boxed = |grow: f64| {
                                let lo = [0, 1, 2].map(|a| {
                                    plane(a, c[a])
                                        - f64::from(shape.margin[a]) * (1.0 + grow)
                                        - grow * f64::from(shape.cell_size[a])
                                });
                                let hi = [0, 1, 2].map(|a| {
                                    plane(a, c[a] + 1)
                                        + f64::from(shape.margin[a]) * (1.0 + grow)
                                        + grow * f64::from(shape.cell_size[a])
                                });
                                sat_overlaps(tri, lo, hi)
                            };
                            let index = cells.index(c);
                            let listed = sorted.binary_search(&index).is_ok();
                            if boxed(-1e-9) {
                                want += 1;
                                assert!(listed, "scene {s} λ {}: {tri:?} not in {c:?}", p.density);
                            } else if listed {
                                assert!(
                                    boxed(1.0 / 512.0),
                                    "scene {s} λ {}: {tri:?} listed in {c:?}, which it misses",
                                    p.density
                                );
                            }
                        }
                    }
                }
                assert!(want >= 1 || got.is_empty());
                long += usize::from(got.len() >= 8);
            }
        }
    }
    assert!(
        long > 1000,
        "only {long} triangles over 8 cells: the test reaches no long ones"
    );
}

/// Directions too small to invert in f32 (on every axis, or on the only moving axis of a scene far
/// from the origin, where t overflows) used to spin forever; they must end and agree.
#[test]
fn tiny_directions_end_and_agree_with_brute_force() {
    for (scale, offset) in [(1.0, [0.0; 3]), (1e-30, [0.0; 3])] {
        let data = procedural::closed_sphere(6).transformed(scale, offset);
        let mut budget = MemoryBudget::new(0);
        let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
        let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
        let b = mesh.bounds();
        let center = 0.5 * (b.min + b.max);
        for d in [
            Vec3::new(1e-45, 0.0, 0.0),
            Vec3::new(-1e-45, 1e-45, 0.0),
            Vec3::new(0.0, 1e-30, 0.0),
            Vec3::new(0.0, -1e-30, 3e-39),
            Vec3::new(2e-39, 2e-39, 2e-39),
        ] {
            for org in [center, b.min, center + 0.4 * (b.max - b.min)] {
                agree(&mesh, &grid, &Ray::new(org, d));
                agree(&mesh, &grid, &Ray::segment(org, d, 0.0, f32::MAX));
            }
        }
    }
}

/// Stepping over empty blocks visits exactly the cells with triangles that the cell-by-cell walk
/// visits: per ray, the same hit and the same number of triangles listed in the cells visited. The
/// rays include diagonals from cell corners of a cubic grid, which cross planes of two or three
/// axes at the same `t` (the walk's ties), and rays that start inside the grid. (It also checks
/// the build's count of the largest cell against the lists.)
#[test]
fn skipping_empty_blocks_lists_what_the_cell_walk_lists() {
    let scenes = [
        procedural::closed_sphere(5),
        procedural::by_name("sphereflake", 10_000).unwrap(),
        procedural::by_name("mount", 4_000).unwrap(),
        procedural::by_name("stadium", 4_000).unwrap(),
        procedural::by_name("hair", 2_000).unwrap(),
    ];
    let mut rng = crate::workload::SplitMix64::new(0xb10c);
    let mut skipped_any = false;
    for data in &scenes {
        let mut budget = MemoryBudget::new(0);
        let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
        let params = GridParams::FINE;
        let grid = UniformGrid::build(&mesh, &params, &mut budget).unwrap();
        let mut cells = UniformGrid::build(&mesh, &params, &mut budget).unwrap();
        cells.blocks.occupy_all();
        let (lo, size) = (grid.shape.bounds.min, grid.shape.cell_size);
        let res = grid.resolution();
        let mut rays = Vec::new();
        for _ in 0..3000 {
            // A cell corner (inside or on the faces of the grid) and a diagonal or random direction.
            let corner = Vec3::new(
                (rng.next_u64() % u64::from(res[0] + 1)) as f32,
                (rng.next_u64() % u64::from(res[1] + 1)) as f32,
                (rng.next_u64() % u64::from(res[2] + 1)) as f32,
            );
            let org = lo + corner * size;
            let sign = |bit: u64| if bit & 1 == 0 { 1.0 } else { -1.0 };
            let bits = rng.next_u64();
            let diagonal = Vec3::new(sign(bits), sign(bits >> 1), sign(bits >> 2)) * size;
            let random = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
            );
            rays.push(Ray::new(org, diagonal));
            rays.push(Ray::new(org, random));
            // From outside the box, through the corner.
            rays.push(Ray::new(org - 3.0 * random * size * res[0] as f32, random));
        }
        for ray in &rays {
            let (mut with, mut without) = (GridWork::default(), GridWork::default());
            let a = grid.intersect_counted(&mesh, ray, &mut with);
            let b = cells.intersect_counted(&mesh, ray, &mut without);
            assert!(a.same_bits(&b), "{ray:?}: {a:?} against {b:?}");
            assert_eq!(with.tests, without.tests, "{ray:?}");
            skipped_any |= with.cells < without.cells;
            agree(&mesh, &grid, ray);
        }
        // The largest cell counted in the build is the longest list, padding excluded.
        let longest = (0..grid.cell_count()).map(|c| grid.listed(c)).max();
        assert_eq!(grid.largest_cell() as u32, longest.unwrap_or(0));
    }
    assert!(skipped_any, "no ray stepped over an empty block");
}
