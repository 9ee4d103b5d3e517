//! Unit tests of the grid: the voxelization against a cell-by-cell separating-axis test, and rays
//! whose direction used to break the walk.

use alloc::vec::Vec;
use glam::Vec3;

use super::layout::Shape;
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

/// Checks the cells `listed` (sorted) for a triangle of a grid of shape `shape` against the
/// oracle, on every cell within two of its bounds: each cell whose box enlarged by the margin the
/// triangle meets is listed, and each cell listed is met within the margin plus the rounding slack
/// (1/512 of a cell). Returns the cells the triangle meets.
pub(super) fn assert_listed_exactly(
    shape: &Shape,
    cells: &Cells,
    tri: &[Vec3; 3],
    listed: &[usize],
    what: &str,
) -> usize {
    let res = shape.res;
    let plane = |a: usize, k: u32| {
        f64::from(shape.bounds.min[a]) + f64::from(k) * f64::from(shape.cell_size[a])
    };
    let b = Aabb::of_triangle(tri);
    let range = |a: usize| {
        let f = |x: f32| {
            ((f64::from(x) - f64::from(shape.bounds.min[a])) / f64::from(shape.cell_size[a]))
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
                let is_listed = listed.binary_search(&cells.index(c)).is_ok();
                if boxed(-1e-9) {
                    want += 1;
                    assert!(is_listed, "{what}: {tri:?} not in {c:?}");
                } else if is_listed {
                    assert!(
                        boxed(1.0 / 512.0),
                        "{what}: {tri:?} listed in {c:?}, which it misses"
                    );
                }
            }
        }
    }
    want
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
                let what = alloc::format!("scene {s} λ {}", p.density);
                let want = assert_listed_exactly(shape, &cells, tri, &sorted, &what);
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
        // The largest cell counted in the build is the longest list tested whole, padding
        // excluded: of a cell without a nested grid, or in a nested grid.
        let nested = grid.nested_cells();
        let outer = (0..grid.cell_count())
            .filter(|c| !nested.contains(c))
            .map(|c| grid.listed(c));
        let inner = grid.nested.iter().flat_map(|n| {
            let g = &n.grid;
            (0..g.cell_count())
                .map(move |c| g.listed(c))
                .chain(core::iter::once(n.large_count))
        });
        let longest = outer.chain(inner).max();
        assert_eq!(grid.largest_cell() as u32, longest.unwrap_or(0));
    }
    assert!(skipped_any, "no ray stepped over an empty block");
}

/// Content slabs (content.rs): a cell whose triangles lie in a thin slab is passed over by a line
/// that misses the slab in its window, and no hit is lost. On a stadium (a floor of large
/// triangles at z = 0 and a sphere on it): a floor cell's slab is passed by a line going up from
/// above it and not by one going down; and rays leaving the floor upwards from heights down to 0,
/// grazing it, lying in its plane, starting on it with `tmin` 0 or above it, and aimed at the
/// sphere past the floor, all agree with brute force (closest hit bit for bit, any hit).
#[test]
fn content_slabs_pass_over_cells_and_lose_no_hit() {
    let data = procedural::teapot_in_stadium(2_000, 2_000);
    let mut budget = MemoryBudget::new(0);
    let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
    let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
    let shape = grid.shape;
    let cell_of = |p: Vec3| {
        let c = ((p - shape.bounds.min) / shape.cell_size).floor();
        c.x as usize + shape.res[0] as usize * (c.y as usize + shape.res[1] as usize * c.z as usize)
    };
    let index = cell_of(Vec3::new(300.0, 200.0, 0.0));
    assert!(grid.cell(index).2, "a floor cell's slab is worth a test");
    let line = |dz: f32, t1: f32| match walk::Plan::entering(
        &grid,
        &Ray::segment(
            Vec3::new(300.0, 200.0, 0.5),
            Vec3::new(0.0, 0.0, dz),
            0.0,
            t1,
        ),
    ) {
        Some(walk::Plan::Walk(line)) => line,
        _ => panic!("the ray walks the grid"),
    };
    // SAFETY: the cell is flagged (above).
    let misses = |dz: f32, t1: f32| unsafe { grid.content.misses(index, &line(dz, t1), t1) };
    assert!(misses(1.0, f32::INFINITY));
    assert!(!misses(-1.0, f32::INFINITY));
    // The window matters: going down, the floor is at t = 0.5.
    assert!(misses(-1.0, 0.49));
    assert!(!misses(-1.0, 0.51));

    let mut rng = crate::workload::SplitMix64::new(0x51ab);
    let mut rays = Vec::new();
    for _ in 0..4000 {
        let on = Vec3::new(
            -500.0 + 1000.0 * rng.next_f32(),
            -300.0 + 600.0 * rng.next_f32(),
            0.0,
        );
        let h = [0.0, 1e-7, 1e-4, 0.01, 0.6][(rng.next_u64() % 5) as usize];
        let org = on + Vec3::new(0.0, 0.0, h);
        let flat = Vec3::new(rng.next_f32() - 0.5, rng.next_f32() - 0.5, 0.0);
        let dz = [0.0, 1e-6, -1e-6, 0.3, -0.3, 1.0][(rng.next_u64() % 6) as usize];
        let d = flat + Vec3::new(0.0, 0.0, dz);
        rays.push(Ray::new(org, d));
        rays.push(Ray::segment(org, d, 1e-3, f32::MAX));
        rays.push(Ray::segment(org, d, 0.0, 50.0 * rng.next_f32()));
        // At the sphere, across the floor cells around it.
        rays.push(Ray::new(org, Vec3::new(0.0, 0.0, 0.5) - org));
    }
    // The indexed layout has no slabs.
    let indexed = GridParams {
        layout: TriangleLayout::Indexed,
        ..GridParams::DEFAULT
    };
    let ids = UniformGrid::build(&mesh, &indexed, &mut budget).unwrap();
    assert!(!ids.content.is_some());
    #[cfg(feature = "std")]
    let passed_before = content::PASSED.with(|n| n.get());
    for ray in &rays {
        agree(&mesh, &grid, ray);
        agree(&mesh, &ids, ray);
    }
    // The walk used the slabs (otherwise the comparisons above would test nothing new): a ray
    // going up from just above the floor passes its cell, and the set passes many.
    #[cfg(feature = "std")]
    {
        let passed = content::PASSED.with(|n| n.get()) - passed_before;
        assert!(
            passed > rays.len() / 10,
            "the walk passed over {passed} cells"
        );
        let before = content::PASSED.with(|n| n.get());
        let up = Ray::new(Vec3::new(300.0, 200.0, 1e-3), Vec3::new(0.1, 0.05, 1.0));
        agree(&mesh, &grid, &up);
        assert!(content::PASSED.with(|n| n.get()) > before);
    }
}

/// Rejects the hits of odd-numbered triangles (an accepting query's filter).
struct EvenOnly;

impl crate::triangle::Accept for EvenOnly {
    fn accept(&self, prim: u32, _hit: &crate::triangle::TriHit) -> bool {
        prim % 2 == 0
    }
}

/// A cell's nested grid answers as the cell's whole list does. On scenes whose dense object lies in
/// a few cells of a grid sized for the whole (which get nested grids), per
/// ray: the same closest hit bit for bit as the same grid without nesting, the same any-hit answer,
/// the brute force's answer, the same with an accept filter (the nested walk's kernel chooses its
/// axes per call), and the counted walk's hit. Rays come at the object from around it, start inside
/// its cells, hit anywhere in the nested cells (near their faces too), come from far away (the far
/// walk, whose entry point and window differ), stop short of it (`tmax`), and have tiny direction
/// components (scaled walks). The nested walks must also list far fewer triangles than the whole
/// lists: otherwise the comparison would test nothing.
#[test]
fn nested_grids_answer_as_the_whole_lists_do() {
    // A cluster of small triangles at the centre of a large sphere, and the teapot in a stadium.
    let mut cluster = procedural::closed_sphere(40).transformed(10.0, [0.0; 3]);
    cluster.append(&procedural::random_soup(3000, 5, 0.05).transformed(0.2, [-0.1; 3]));
    // The field's triangles in the sphere's cell are larger than the cell: tested whole.
    let stadium = procedural::teapot_in_stadium(6_000, 2_000);
    nesting_agrees(&cluster, Vec3::ZERO, 2000, false);
    nesting_agrees(&stadium, Vec3::new(0.0, 0.0, 0.5), 4000, true);
}

/// [`nested_grids_answer_as_the_whole_lists_do`] on a scene with nested grids, with `n` rays at the
/// dense object around `centre`; `large`: whether a nested cell also holds triangles larger than
/// itself (tested whole).
fn nesting_agrees(data: &MeshData, centre: Vec3, n: usize, large: bool) {
    let mut budget = MemoryBudget::new(0);
    let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
    let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
    let mut whole = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
    whole.drop_nested(&mut budget);
    assert_eq!(grid.nesting_depth(), 1);
    assert_eq!(grid.nested.iter().any(|n| n.large_count > 0), large);
    assert_eq!(whole.nested_count(), 0);
    let brute = BruteForce::new(&mesh);
    let mut rng = crate::workload::SplitMix64::new(0x0e57);
    let mut random = |scale: f32| {
        let v = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        );
        (v * scale, rng.next_f32())
    };
    // The nested cells' boxes, for rays that hit anywhere in them, near their faces too.
    let boxes: Vec<Aabb> = grid
        .nested_cells()
        .into_iter()
        .map(|c| nested::enlarged_cell(&grid, c))
        .collect();
    let (mut tests_nested, mut tests_whole) = (0u64, 0u64);
    for i in 0..n {
        let target = centre + random(1.4).0;
        let (dir, stop) = random(2.0);
        let in_cell = |r: (Vec3, f32)| {
            let b = boxes[i % boxes.len()];
            let p = b.min + (r.0 / 2.0 + Vec3::splat(0.5)) * (b.max - b.min);
            Vec3::new(p.x, p.y, (r.1 - 0.2) * 1.5)
        };
        let ray = match i % 8 {
            // Anywhere in a nested cell, on the field or the sphere.
            6 | 7 => Ray::new(in_cell(random(2.0)) - dir * 20.0, dir),
            0 => Ray::new(target - dir * 30.0, dir),
            1 => Ray::new(target - dir * 2000.0, dir),
            // Inside the sphere's cells, or on its surface.
            2 => Ray::new(centre + random(1.2).0, dir),
            // From so far that the nested grids' walks take the far path.
            3 => Ray::new(target - dir * 3e6, dir),
            // Stopping at or before the sphere.
            4 => Ray::segment(target - dir * 30.0, dir, 0.0, 29.5 + 2.0 * stop),
            // A direction with two components near zero.
            _ => Ray::new(target - Vec3::Z * 40.0, Vec3::new(1e-30, -2e-39, 1.0)),
        };
        let (a, b) = (grid.intersect(&mesh, &ray), whole.intersect(&mesh, &ray));
        assert!(a.same_bits(&b), "{ray:?}: nested {a:?}, whole lists {b:?}");
        assert_eq!(
            grid.occluded(&mesh, &ray),
            whole.occluded(&mesh, &ray),
            "{ray:?}"
        );
        let want = brute.intersect(&mesh, &ray);
        assert!(a.same_bits(&want), "{ray:?}: {a:?}, brute force {want:?}");
        let (fa, fb) = (
            grid.intersect_accepting(&mesh, &ray, Some(&EvenOnly)),
            brute.intersect_accepting(&mesh, &ray, Some(&EvenOnly)),
        );
        assert!(
            fa.same_bits(&fb),
            "{ray:?}: filtered {fa:?}, brute force {fb:?}"
        );
        assert_eq!(
            grid.occluded_accepting(&mesh, &ray, Some(&EvenOnly)),
            fb.is_hit(),
            "{ray:?}"
        );
        let (mut with, mut without) = (GridWork::default(), GridWork::default());
        let c = grid.intersect_counted(&mesh, &ray, &mut with);
        whole.intersect_counted(&mesh, &ray, &mut without);
        assert!(c.same_bits(&a), "{ray:?}: counted {c:?}, {a:?}");
        tests_nested += u64::from(with.tests);
        tests_whole += u64::from(without.tests);
    }
    assert!(
        tests_nested * 10 < tests_whole,
        "nested walks listed {tests_nested} triangles, whole lists {tests_whole}"
    );
}

/// Nested grids are optional: a memory limit that leaves no room for them still builds the outer
/// grid (without them, answering the same), and a cluster far from the origin against its size,
/// where a nested grid's margin would swamp its cells, gets none.
#[test]
fn nested_grids_give_way_to_the_memory_limit_and_far_offsets() {
    let mut cluster = procedural::closed_sphere(40).transformed(10.0, [0.0; 3]);
    cluster.append(&procedural::random_soup(3000, 5, 0.05).transformed(0.2, [-0.1; 3]));
    let mut unlimited = MemoryBudget::new(0);
    let mesh = TriMesh::from_source(&cluster.as_source(), &mut unlimited).unwrap();
    let full = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
    assert!(full.nested_count() > 0);
    let mut without = None;
    let mut limit = full.memory_bytes() + 1;
    while limit > 1024 {
        let mut budget = MemoryBudget::new(limit);
        match UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget) {
            Ok(grid) if grid.nested_count() == 0 => {
                without = Some(grid);
                break;
            }
            Ok(_) => limit = limit * 9 / 10,
            Err(_) => break,
        }
    }
    let grid = without.expect("no limit built the outer grid without its nested grids");
    let mut rng = crate::workload::SplitMix64::new(9);
    for _ in 0..300 {
        let d = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        );
        let ray = Ray::new(Vec3::splat(0.05) * rng.next_f32(), d);
        let (a, b) = (grid.intersect(&mesh, &ray), full.intersect(&mesh, &ray));
        assert!(a.same_bits(&b), "{ray:?}: {a:?} against {b:?}");
    }
    // The same cluster 10^6 of its sizes from the origin: no nested grid, the same answers.
    let far = cluster.transformed(1.0, [2e5, 0.0, 0.0]);
    let far_mesh = TriMesh::from_source(&far.as_source(), &mut unlimited).unwrap();
    let mut far_budget = MemoryBudget::new(0);
    let far_grid = UniformGrid::build(&far_mesh, &GridParams::DEFAULT, &mut far_budget).unwrap();
    assert_eq!(far_grid.nested_count(), 0);
    // Not even tried: built, it would list each triangle in most of its cells.
    assert!(
        far_budget.peak() < 3 * far_grid.memory_bytes(),
        "peak {} for a grid of {}",
        far_budget.peak(),
        far_grid.memory_bytes()
    );
    for _ in 0..100 {
        let d = Vec3::new(
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
            rng.next_f32() - 0.5,
        );
        agree(&far_mesh, &far_grid, &Ray::new(Vec3::new(2e5, 0.0, 0.0), d));
    }
}

/// The build lists each triangle in exactly the cells `Cells::for_each` gives it (the build
/// stores a small footprint's cells its own way), each list sorted by id, in both layouts: on
/// well-shaped scenes, long triangles (large footprints) and a mesh with degenerate triangles.
#[test]
fn built_lists_are_the_voxelization() {
    let mut flat = procedural::random_soup(300, 9, 0.3);
    // Degenerate triangles among the live ones: repeated and collinear vertices.
    for k in 0..20 {
        let x = k as f32 / 20.0;
        let base = flat.vertices.len() as u32;
        flat.vertices
            .extend([[x, 0.1, 0.2], [x + 0.1, 0.2, 0.3], [x + 0.2, 0.3, 0.4]]);
        flat.indices.push([base, base + 1, base + 2]);
        flat.indices.push([base, base, base + 1]);
    }
    let scenes = [
        procedural::random_slivers(800, 3),
        procedural::hair(100, 4, 5),
        procedural::teapot_in_stadium(100, 300),
        flat,
    ];
    for data in &scenes {
        for layout in [TriangleLayout::Packed, TriangleLayout::Indexed] {
            for density in [0.125, 0.5, 2.0, 8.0] {
                let params = GridParams {
                    density,
                    exact_overlap: true,
                    layout,
                };
                let mut budget = MemoryBudget::new(0);
                let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
                let grid = UniformGrid::build(&mesh, &params, &mut budget).unwrap();
                let cells = Cells::new(&grid.shape);
                let mut want = alloc::vec![Vec::new(); grid.shape.cells()];
                for (prim, tri) in mesh.triangles().iter().enumerate() {
                    if !mesh.is_degenerate(prim as u32) {
                        cells.for_each(tri, true, &mut |c| want[c as usize].push(prim as u32));
                    }
                }
                for (c, want) in want.iter().enumerate() {
                    let (start, end) = grid.span(c);
                    let got: Vec<u32> = match &grid.lists {
                        Lists::Packed { ids, .. } => ids[start..end]
                            .as_flattened()
                            .iter()
                            .copied()
                            .filter(|&id| id != Hit::INVALID_ID)
                            .collect(),
                        Lists::Indexed { ids, .. } => ids[start..end].to_vec(),
                    };
                    assert_eq!(&got, want, "cell {c}, density {density}, {layout:?}");
                }
                grid.release(&mut budget);
            }
        }
    }
}

/// Memory limits through the build's growth paths: each build either fits, with the unlimited
/// build's lists, or fails with every byte given back. The first scene (9–30 references a
/// triangle, past the scratch's first guess of 3) grows it on large footprints; the second, long
/// hairs that fill the guess and then small triangles, grows it on small ones (at density 32: seen
/// with a count in the small footprints' growth, 1 480 triangles growing at 4 433 references).
#[test]
fn a_build_under_any_memory_limit_is_whole_or_nothing() {
    let mut long = procedural::random_soup(400, 11, 0.4);
    long.append(&procedural::hair(30, 4, 5));
    whole_or_nothing_under_limits(&long);
    let mut small_last = procedural::hair(60, 4, 5);
    small_last.append(&procedural::random_soup(1000, 12, 0.005));
    whole_or_nothing_under_limits(&small_last);
}

/// [`a_build_under_any_memory_limit_is_whole_or_nothing`] on one scene, both layouts, densities 2
/// and 32.
fn whole_or_nothing_under_limits(data: &MeshData) {
    let mut unlimited = MemoryBudget::new(0);
    let mesh = TriMesh::from_source(&data.as_source(), &mut unlimited).unwrap();
    let base = unlimited.used();
    for layout in [TriangleLayout::Packed, TriangleLayout::Indexed] {
        for density in [2.0f32, 32.0] {
            let params = GridParams {
                density,
                exact_overlap: true,
                layout,
            };
            let full = UniformGrid::build(&mesh, &params, &mut MemoryBudget::new(0)).unwrap();
            let (mut fitted, mut refused) = (0, 0);
            let mut limit = base + 1;
            while limit < base + 4 * full.memory_bytes() + (1 << 20) {
                let mut budget = MemoryBudget::new(limit);
                budget.charge(base, "mesh").unwrap();
                match UniformGrid::build(&mesh, &params, &mut budget) {
                    Ok(g) => {
                        fitted += 1;
                        assert_eq!(g.offsets, full.offsets);
                        match (&g.lists, &full.lists) {
                            (Lists::Packed { ids: a, .. }, Lists::Packed { ids: b, .. }) => {
                                assert_eq!(a, b)
                            }
                            (Lists::Indexed { ids: a, .. }, Lists::Indexed { ids: b, .. }) => {
                                assert_eq!(a, b)
                            }
                            _ => panic!("layouts differ"),
                        }
                        g.release(&mut budget);
                        assert_eq!(budget.used(), base);
                    }
                    Err(_) => {
                        refused += 1;
                        assert_eq!(budget.used(), base, "limit {limit}");
                    }
                }
                limit = limit * 5 / 4 + 64;
            }
            assert!(fitted > 0 && refused > 0, "{fitted} {refused}");
        }
    }
}

/// A dense object in a sparse scene (a teapot in a stadium) does not set the outer grid's
/// resolution: the outer grid is sized for the field, the object gets its nested grid over itself
/// (the field's triangles in its cell, far larger than its own, are tested whole), and no list a
/// walk tests whole is long. A scene without a dense object keeps the grid sized for all of it.
#[test]
fn a_dense_object_does_not_set_the_outer_grids_resolution() {
    let mut budget = MemoryBudget::new(0);
    let cells_for = |live: usize, tight: Aabb| {
        Shape::new(tight, live, GridParams::DEFAULT.density)
            .unwrap()
            .cells()
    };
    for (sphere, field) in [(6_000, 2_000), (30_000, 10_000)] {
        let data = procedural::teapot_in_stadium(sphere, field);
        let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
        let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
        let (all, rest) = (
            cells_for(mesh.len(), mesh.bounds()),
            cells_for(field, mesh.bounds()),
        );
        assert!(grid.cell_count() * 2 < all && grid.cell_count() <= rest * 2);
        assert!(grid.nested_count() >= 1);
        assert!(grid.nested.iter().all(|n| n.large_count > 0));
        assert!(grid.largest_cell() * 16 < sphere, "{}", grid.largest_cell());
        grid.release(&mut budget);
    }
    // Without a dense object, or with one that gets no nested grid (far from the origin, where the
    // margin would swamp its cells), the grid is sized for every triangle.
    let sphere = procedural::closed_sphere(60);
    let far = procedural::teapot_in_stadium(30_000, 10_000).transformed(1.0, [1e6, 1e6, 0.0]);
    for data in [sphere, far] {
        let mesh = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
        let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut budget).unwrap();
        let live = mesh.len() - mesh.degenerate_count();
        assert_eq!(grid.cell_count(), cells_for(live, mesh.bounds()));
        assert_eq!(grid.nested_count(), 0);
        grid.release(&mut budget);
    }
}

/// No axis gets more cells than the insertion's cap can name: at a density that asks for 1.1·10⁹
/// cells along one axis, a triangle near that axis's far end is still listed in its own cell (a
/// review's finding: every triangle past cell 2^30 was listed in that cell alone).
#[test]
fn no_axis_has_a_cell_past_the_insertion_cap() {
    let tight = Aabb {
        min: Vec3::ZERO,
        max: Vec3::new(1.0e6, 0.5, 0.5),
    };
    let shape = Shape::new(tight, 4000, 2.75e5).unwrap();
    assert!(
        shape.res[0] <= super::layout::MAX_AXIS_CELLS,
        "{:?}",
        shape.res
    );
    let cells = Cells::new(&shape);
    let tri = [
        Vec3::new(0.99e6, 0.0, 0.0),
        Vec3::new(0.99e6 + 10.0, 0.5, 0.0),
        Vec3::new(0.99e6, 0.5, 0.5),
    ];
    let fp = cells.footprint(&tri);
    let cell = ((f64::from(tri[0].x) - f64::from(shape.bounds.min.x))
        / f64::from(shape.cell_size.x)) as u32;
    assert!(
        fp.lo[0] <= cell && cell <= fp.hi[0],
        "footprint {fp:?} misses cell {cell} of {:?}",
        shape.res
    );
}
