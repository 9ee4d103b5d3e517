//! Scenes of several geometries: masks, culling by geometry and by ray, any-hit filters, hits with
//! geometry ids and normals, moved vertices. Every structure must give the answer of the definition
//! (the closest hit the conditions accept, ties to the lowest `(geom, prim)`) bit for bit.

mod common;

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use glam::Vec3;
use rayq::geometry::Filter;
use rayq::geometry::{Geometry, HitEx, RayEx, CULL_BACK_FACES, CULL_FRONT_FACES};
use rayq::mesh::{IndexedMesh, MeshData};
use rayq::procedural;
use rayq::scene::{BuildOptions, Structure};
use rayq::triangle::PreparedRay;
use rayq::workload::SplitMix64;
use rayq::{BuildError, Calibration, GridParams, KdTreeParams, Scene, TriangleLayout};

/// Five meshes that overlap: a closed sphere, a terrain, a soup, an empty mesh and a tetrahedron
/// fractal (so rays meet several geometries, in both facings).
fn parts() -> Vec<MeshData> {
    vec![
        procedural::closed_sphere(8).transformed(0.6, [0.0, 0.0, 0.0]),
        procedural::mount(4, 7).transformed(1.5, [-0.75, -0.75, -0.2]),
        procedural::random_soup(300, 3, 0.2).transformed(1.2, [-0.6, -0.6, -0.6]),
        MeshData::default(),
        procedural::tetra(2).transformed(0.8, [-0.1, -0.1, -0.1]),
    ]
}

const MASKS: [u32; 5] = [1, 2, 4 | 1, 8, 2];
const FLAGS: [u32; 5] = [0, CULL_BACK_FACES, 0, 0, CULL_FRONT_FACES];

/// The alpha test of geometries 2 and 4: a deterministic function of the candidate, as a texture
/// lookup would be.
fn alpha(h: &HitEx) -> bool {
    (h.prim % 3 != 0) && (h.u + 0.5 * h.v < 0.7)
}

fn has_filter(g: usize) -> bool {
    g == 2 || g == 4
}

fn geometries<'a>(sources: &'a [IndexedMesh<'a>]) -> Vec<Geometry<'a>> {
    sources
        .iter()
        .enumerate()
        .map(|(g, source)| {
            let mut geometry = Geometry::new(source);
            geometry.mask = MASKS[g];
            geometry.flags = FLAGS[g];
            if has_filter(g) {
                geometry.filter = Some(Box::new(|_: &RayEx, h: &HitEx| alpha(h)));
            }
            geometry
        })
        .collect()
}

/// Camera, bounce and adversarial rays over the union, each with a mask and flags from a cycle.
/// Options that build the grid alone (the selector does not run).
fn grid_only() -> BuildOptions {
    BuildOptions {
        structure: Structure::Grid,
        ..BuildOptions::DEFAULT
    }
}

fn rays(parts: &[MeshData]) -> Vec<RayEx> {
    let mut all = MeshData::default();
    for p in parts {
        all.append(p);
    }
    let mesh = common::mesh_of(&all);
    let masks = [u32::MAX, 1, 2, 4, 3, 0, 6, 8 | 2];
    let flags = [
        0,
        CULL_BACK_FACES,
        0,
        CULL_FRONT_FACES,
        CULL_BACK_FACES | CULL_FRONT_FACES,
    ];
    common::test_rays(&mesh, 32, 400, 11)
        .into_iter()
        .enumerate()
        .map(|(i, ray)| RayEx {
            ray,
            mask: masks[i % masks.len()],
            flags: flags[i / 3 % flags.len()],
        })
        .collect()
}

fn corners(part: &MeshData, i: usize) -> [Vec3; 3] {
    part.triangle(i).map(Vec3::from)
}

/// The definition, triangle by triangle with the public exact test; `None` when the answer rests
/// on a facing this f64 sign cannot settle (a hit seen almost edge-on where culling applies).
fn definition(parts: &[MeshData], ray: &RayEx) -> Option<HitEx> {
    let mut best = HitEx::MISS;
    let Some(prepared) = PreparedRay::new(&ray.ray) else {
        return Some(best);
    };
    let d = ray.ray.dir.as_dvec3();
    for (g, part) in parts.iter().enumerate() {
        for i in 0..part.indices.len() {
            let tri = corners(part, i);
            let Some((t, u, v)) = prepared.intersect_triangle(tri[0], tri[1], tri[2]) else {
                continue;
            };
            if ray.mask & MASKS[g] == 0 {
                continue;
            }
            let (a, b, c) = (tri[0].as_dvec3(), tri[1].as_dvec3(), tri[2].as_dvec3());
            let n = (b - a).cross(c - a);
            let facing = d.dot(n);
            let cull = ray.flags | FLAGS[g];
            if cull != 0 && facing.abs() <= 1e-9 * d.length() * n.length() {
                return None;
            }
            let culled = if facing < 0.0 {
                CULL_FRONT_FACES
            } else {
                CULL_BACK_FACES
            };
            if cull & culled != 0 {
                continue;
            }
            let candidate = HitEx {
                t,
                u,
                v,
                prim: i as u32,
                geom: g as u32,
                ng: (tri[1] - tri[0]).cross(tri[2] - tri[0]),
            };
            if has_filter(g) && !alpha(&candidate) {
                continue;
            }
            let key = |h: &HitEx| (h.t, h.geom, h.prim);
            if !best.is_hit() || key(&candidate) < key(&best) {
                best = candidate;
            }
        }
    }
    Some(best)
}

fn same(a: &HitEx, b: &HitEx) -> bool {
    a.t.to_bits() == b.t.to_bits()
        && a.u.to_bits() == b.u.to_bits()
        && a.v.to_bits() == b.v.to_bits()
        && a.prim == b.prim
        && a.geom == b.geom
        && a.ng.to_array().map(f32::to_bits) == b.ng.to_array().map(f32::to_bits)
}

/// The structures every test runs: grids and kd-trees with several parameter sets.
fn option_sets() -> Vec<(&'static str, BuildOptions)> {
    let grid = |grid: GridParams| BuildOptions {
        structure: Structure::Grid,
        grid,
        ..BuildOptions::DEFAULT
    };
    let kd = |kdtree: KdTreeParams| BuildOptions {
        structure: Structure::KdTree,
        kdtree,
        ..BuildOptions::DEFAULT
    };
    vec![
        ("grid", grid(GridParams::DEFAULT)),
        (
            "grid-indexed-coarse",
            grid(GridParams {
                density: 0.125,
                layout: TriangleLayout::Indexed,
                ..GridParams::DEFAULT
            }),
        ),
        ("kd", kd(KdTreeParams::DEFAULT)),
        (
            "kd-binned-indexed",
            kd(KdTreeParams {
                exact_below: 0,
                layout: TriangleLayout::Indexed,
                ..KdTreeParams::DEFAULT
            }),
        ),
        ("kd-high", kd(KdTreeParams::HIGH)),
    ]
}

#[test]
fn every_structure_gives_the_definitions_answer_under_masks_culling_and_filters() {
    let parts = parts();
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    let rays = rays(&parts);
    let want: Vec<Option<HitEx>> = rays.iter().map(|r| definition(&parts, r)).collect();
    let settled = want.iter().filter(|w| w.is_some()).count();
    assert!(
        settled * 100 >= rays.len() * 99,
        "{settled} of {} rays settled",
        rays.len()
    );
    let hits = want.iter().flatten().filter(|h| h.is_hit()).count();
    eprintln!("{hits} of {} rays hit, {settled} settled", rays.len());
    assert!(
        hits * 8 > rays.len(),
        "only {hits} of {} rays hit",
        rays.len()
    );
    for (name, options) in option_sets() {
        let scene =
            Scene::build_geometries(geometries(&sources), &options, Calibration::builtin(), None)
                .expect("build");
        assert_eq!(scene.report().geometry_count, parts.len());
        for (i, (ray, want)) in rays.iter().zip(&want).enumerate() {
            let got = scene.intersect_ex(ray);
            if let Some(want) = want {
                assert!(
                    same(&got, want),
                    "{name}: ray {i} {ray:?}: got {got:?}, want {want:?}"
                );
            }
            assert_eq!(
                scene.occluded_ex(ray),
                got.is_hit(),
                "{name}: ray {i}: occluded_ex"
            );
        }
    }
}

#[test]
fn conditions_change_the_answers_they_should() {
    // The test above would pass with conditions ignored if no ray met them: count rays whose
    // answer differs from the unconditioned one, for each kind of condition.
    let parts = parts();
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    let rays = rays(&parts);
    let options = grid_only();
    let plain: Vec<Geometry<'_>> = sources.iter().map(|p| Geometry::new(p)).collect();
    let plain = Scene::build_geometries(plain, &options, Calibration::builtin(), None).unwrap();
    let conditioned =
        Scene::build_geometries(geometries(&sources), &options, Calibration::builtin(), None)
            .unwrap();
    let mut by_mask = 0;
    let mut by_cull = 0;
    let mut by_filter = 0;
    for ray in &rays {
        let open = plain.intersect_ex(&RayEx::new(ray.ray));
        let got = conditioned.intersect_ex(ray);
        if same(&open, &got) || !open.is_hit() {
            continue;
        }
        let g = open.geom as usize;
        if ray.mask & MASKS[g] == 0 {
            by_mask += 1;
        } else if (ray.flags | FLAGS[g]) != 0 && !has_filter(g) {
            by_cull += 1;
        } else {
            by_filter += 1;
        }
    }
    assert!(
        by_mask > 50 && by_cull > 50 && by_filter > 20,
        "{by_mask} {by_cull} {by_filter}"
    );
}

#[test]
fn plain_queries_count_triangles_across_geometries_and_keep_the_conditions() {
    let parts = parts();
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    let rays = rays(&parts);
    let scene = Scene::build_geometries(
        geometries(&sources),
        &BuildOptions::DEFAULT,
        Calibration::builtin(),
        None,
    )
    .unwrap();
    let starts: Vec<u32> = parts
        .iter()
        .scan(0u32, |s, p| {
            let start = *s;
            *s += p.indices.len() as u32;
            Some(start)
        })
        .collect();
    for ray in &rays {
        let ex = scene.intersect_ex(&RayEx::new(ray.ray));
        let hit = scene.intersect(&ray.ray);
        assert_eq!(hit.is_hit(), ex.is_hit());
        assert_eq!(scene.occluded(&ray.ray), hit.is_hit());
        if hit.is_hit() {
            assert_eq!(hit.prim, starts[ex.geom as usize] + ex.prim);
            assert_eq!(
                (hit.t.to_bits(), hit.u.to_bits(), hit.v.to_bits()),
                (ex.t.to_bits(), ex.u.to_bits(), ex.v.to_bits())
            );
            let tri = corners(&parts[ex.geom as usize], ex.prim as usize);
            assert_eq!(ex.ng, (tri[1] - tri[0]).cross(tri[2] - tri[0]));
        }
    }
}

/// The alpha test of geometry 2, counting its calls and the calls about a candidate the public
/// exact test does not confirm (a triangle missed, or another `t`, `u`, `v`).
fn checking_alpha(
    part: &MeshData,
    calls: &Arc<AtomicUsize>,
    wrong: &Arc<AtomicUsize>,
) -> Box<Filter> {
    let (part, calls, wrong) = (part.clone(), calls.clone(), wrong.clone());
    Box::new(move |ray: &RayEx, h: &HitEx| {
        calls.fetch_add(1, Ordering::Relaxed);
        let tri = corners(&part, h.prim as usize);
        let really = PreparedRay::new(&ray.ray)
            .and_then(|p| p.intersect_triangle(tri[0], tri[1], tri[2]))
            .map(|(t, u, v)| [t, u, v].map(f32::to_bits));
        if h.geom != 2 || really != Some([h.t, h.u, h.v].map(f32::to_bits)) {
            wrong.fetch_add(1, Ordering::Relaxed);
        }
        alpha(h)
    })
}

#[test]
fn a_filter_is_asked_only_about_triangles_the_ray_hits() {
    let parts = parts();
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    let rays = rays(&parts);
    for structure in [Structure::Grid, Structure::KdTree] {
        let (calls, wrong) = (Arc::new(AtomicUsize::new(0)), Arc::new(AtomicUsize::new(0)));
        let mut geometries = geometries(&sources);
        geometries[2].filter = Some(checking_alpha(&parts[2], &calls, &wrong));
        let options = BuildOptions {
            structure,
            ..BuildOptions::DEFAULT
        };
        let scene =
            Scene::build_geometries(geometries, &options, Calibration::builtin(), None).unwrap();
        for ray in &rays {
            scene.intersect_ex(ray);
            scene.occluded_ex(ray);
        }
        assert_eq!(wrong.load(Ordering::Relaxed), 0, "{structure:?}");
        eprintln!("{structure:?}: {} calls", calls.load(Ordering::Relaxed));
        assert!(
            calls.load(Ordering::Relaxed) > 100,
            "{structure:?}: the filter was not asked"
        );
    }
}

/// Moves every vertex of `part` by `f`.
fn moved(part: &MeshData, f: impl Fn([f32; 3]) -> [f32; 3]) -> MeshData {
    MeshData {
        vertices: part.vertices.iter().map(|&p| f(p)).collect(),
        indices: part.indices.clone(),
    }
}

#[test]
fn moved_vertices_answer_as_a_fresh_build_of_the_moved_meshes() {
    let parts = parts();
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    let rays = rays(&parts);
    let shift = |p: [f32; 3]| [p[0] * 0.7 + 0.3, p[1] * 1.1, p[2] - 0.25];
    let mut after = parts.clone();
    after[1] = moved(&parts[1], shift);
    let after_sources: Vec<IndexedMesh<'_>> = after.iter().map(MeshData::as_source).collect();
    for (name, options) in option_sets().into_iter().chain([
        (
            "auto-many-rays",
            BuildOptions {
                expected_rays: 1 << 40,
                ..BuildOptions::DEFAULT
            },
        ),
        ("auto-unknown-budget", BuildOptions::DEFAULT),
    ]) {
        let mut scene =
            Scene::build_geometries(geometries(&sources), &options, Calibration::builtin(), None)
                .unwrap();
        let fresh = Scene::build_geometries(
            geometries(&after_sources),
            &options,
            Calibration::builtin(),
            None,
        )
        .unwrap();
        let source = &after[1];
        scene
            .set_vertices(1, &|i| source.vertices[i])
            .expect("move");
        assert_eq!(scene.report().structure, fresh.report().structure, "{name}");
        assert_eq!(
            scene.report().memory_bytes,
            fresh.report().memory_bytes,
            "{name}"
        );
        for (i, ray) in rays.iter().enumerate() {
            let (got, want) = (scene.intersect_ex(ray), fresh.intersect_ex(ray));
            assert!(
                same(&got, &want),
                "{name}: ray {i}: moved {got:?}, fresh {want:?}"
            );
        }
    }
}

#[test]
fn a_refused_move_leaves_the_scene_as_it_was() {
    let parts = parts();
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    let rays = rays(&parts);
    let options = grid_only();
    let mut scene =
        Scene::build_geometries(geometries(&sources), &options, Calibration::builtin(), None)
            .unwrap();
    let before: Vec<HitEx> = rays.iter().map(|r| scene.intersect_ex(r)).collect();
    let report = scene.report();
    let nan = |i: usize| {
        if i == 5 {
            [f32::NAN, 0.0, 0.0]
        } else {
            [0.0; 3]
        }
    };
    assert!(matches!(
        scene.set_vertices(1, &nan),
        Err(BuildError::InvalidGeometry { geometry: 1, .. })
    ));
    assert!(matches!(
        scene.set_vertices(9, &|_| [0.0; 3]),
        Err(BuildError::InvalidArgument { .. })
    ));
    // The smallest limit a build fits in holds the scene but not a second grid beside it.
    let limited = |limit: usize| {
        Scene::build_geometries(
            geometries(&sources),
            &BuildOptions {
                memory_limit: limit,
                ..options
            },
            Calibration::builtin(),
            None,
        )
    };
    let (mut lo, mut hi) = (1usize, 64 * report.memory_bytes);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if limited(mid).is_ok() {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    let mut tight = limited(hi).unwrap();
    assert!(matches!(
        tight.set_vertices(0, &|i| parts[0].vertices[i].map(|c| c * 2.0)),
        Err(BuildError::MemoryLimit { .. })
    ));
    for (scene, name) in [(&scene, "refused"), (&tight, "over the limit")] {
        // Debug text: the report's NaN estimates are not equal to themselves.
        assert_eq!(
            format!("{:?}", scene.report()),
            format!("{report:?}"),
            "{name}"
        );
        for (i, ray) in rays.iter().enumerate() {
            assert!(
                same(&scene.intersect_ex(ray), &before[i]),
                "{name}: ray {i}"
            );
        }
    }
}

#[test]
fn a_ray_with_mask_zero_sees_nothing_and_a_scene_of_one_mesh_is_geometry_zero() {
    let sphere = procedural::closed_sphere(6);
    let scene = Scene::build(
        &sphere.as_source(),
        &BuildOptions::DEFAULT,
        Calibration::builtin(),
    )
    .unwrap();
    assert_eq!(scene.report().geometry_count, 1);
    let mut rng = SplitMix64::new(5);
    for _ in 0..200 {
        let ray = rayq::Ray::new(Vec3::ZERO, rng.unit_vector());
        let hit = scene.intersect_ex(&RayEx::new(ray));
        assert!(hit.is_hit());
        assert_eq!(hit.geom, 0);
        assert_eq!(hit.prim, scene.intersect(&ray).prim);
        assert!(!scene
            .intersect_ex(&RayEx {
                mask: 0,
                ..RayEx::new(ray)
            })
            .is_hit());
        // From inside, a closed sphere shows only back faces.
        let cull_back = RayEx {
            flags: CULL_BACK_FACES,
            ..RayEx::new(ray)
        };
        assert!(!scene.occluded_ex(&cull_back));
    }
}
