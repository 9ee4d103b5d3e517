//! What the conditions of scenes of several geometries cost, and that the plain path does not pay
//! for them: queries per second on the same scene and rays, as a scene of one mesh (`plain`), as the
//! same triangles split into two geometries without conditions (`two-geometries`, the plain path),
//! with geometry masks (1 and 3) that every ray (mask 1) passes (`mask`), and with a filter that
//! accepts every candidate (`filter`: the price of asking per candidate hit).
//!
//!     cargo bench --bench geometries
//!
//! Scene: bunny from ../shared/scenes when present, else scenes/teapot.obj; camera rays (256²) and
//! their diffuse bounces; grid and kd-tree forced. The before/after comparison of the plain path
//! (callgrind, same rays) is in docs/performance.md.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayq::geometry::{Geometry, HitEx, RayEx};
use rayq::mesh::{IndexedMesh, MeshData};
use rayq::scene::{BuildOptions, Structure};
use rayq::workload::{bounce_rays, camera_rays, SplitMix64};
use rayq::{Calibration, Ray, Scene};

fn scene_data() -> (&'static str, MeshData) {
    let bunny = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/scenes/bunny.obj");
    let teapot = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes/teapot.obj");
    match rayq::obj::load_obj(bunny) {
        Ok(m) => ("bunny", m),
        Err(_) => (
            "teapot",
            rayq::obj::load_obj(teapot).expect("scenes/teapot.obj"),
        ),
    }
}

/// The mesh's triangles split in two halves (each a mesh over all the vertices).
fn halves(data: &MeshData) -> [MeshData; 2] {
    let mid = data.indices.len() / 2;
    [
        MeshData {
            vertices: data.vertices.clone(),
            indices: data.indices[..mid].to_vec(),
        },
        MeshData {
            vertices: data.vertices.clone(),
            indices: data.indices[mid..].to_vec(),
        },
    ]
}

fn bench(c: &mut Criterion) {
    let (name, data) = scene_data();
    let parts = halves(&data);
    let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
    for structure in [Structure::Grid, Structure::KdTree] {
        let options = BuildOptions {
            structure,
            ..BuildOptions::DEFAULT
        };
        let plain = Scene::build(&data.as_source(), &options, Calibration::builtin()).unwrap();
        let mut rng = SplitMix64::new(3);
        let mut rays: Vec<Ray> = camera_rays(&plain.mesh().bounds(), 256, &mut rng);
        let hits: Vec<_> = rays.iter().map(|r| plain.intersect(r)).collect();
        let bounces = bounce_rays(plain.mesh(), &rays, &hits, &mut rng);
        rays.extend(bounces);
        // `masks`: the geometries' masks; `filtered`: a filter on each.
        let two = |masks: [u32; 2], filtered: bool| {
            let geometries = sources
                .iter()
                .zip(masks)
                .map(|(s, mask)| {
                    let mut g = Geometry::new(s);
                    g.mask = mask;
                    if filtered {
                        g.filter = Some(Box::new(|_: &RayEx, h: &HitEx| h.t.is_finite()));
                    }
                    g
                })
                .collect();
            Scene::build_geometries(geometries, &options, Calibration::builtin(), None).unwrap()
        };
        let unconditioned = two([u32::MAX; 2], false);
        let with_masks = two([1, 3], false);
        let filtered = two([u32::MAX; 2], true);
        let masked: Vec<RayEx> = rays
            .iter()
            .map(|&ray| RayEx {
                ray,
                mask: 1,
                flags: 0,
            })
            .collect();
        let open: Vec<RayEx> = rays.iter().map(|&ray| RayEx::new(ray)).collect();

        let mut group = c.benchmark_group(format!("geometries/{name}/{structure:?}"));
        group
            .throughput(Throughput::Elements(rays.len() as u64))
            .sample_size(20)
            .measurement_time(Duration::from_secs(6));
        group.bench_function("plain", |b| {
            b.iter(|| {
                rays.iter()
                    .filter(|r| plain.intersect(black_box(r)).is_hit())
                    .count()
            })
        });
        group.bench_function("two-geometries", |b| {
            b.iter(|| {
                open.iter()
                    .filter(|r| unconditioned.intersect_ex(black_box(r)).is_hit())
                    .count()
            })
        });
        group.bench_function("mask", |b| {
            b.iter(|| {
                masked
                    .iter()
                    .filter(|r| with_masks.intersect_ex(black_box(r)).is_hit())
                    .count()
            })
        });
        group.bench_function("filter", |b| {
            b.iter(|| {
                open.iter()
                    .filter(|r| filtered.intersect_ex(black_box(r)).is_hit())
                    .count()
            })
        });
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
