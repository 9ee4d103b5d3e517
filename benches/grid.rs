//! Grid build time and closest-hit rays/s on a uniform-ish scene and a "teapot in a stadium".
//!
//!     cargo bench --bench grid
//!
//! Scenes: dragon_res2 (202k triangles, scanned, uniform surface; from ../shared/scenes when present,
//! else a procedural sphereflake of the same size) and a procedural teapot-in-a-stadium of 200k
//! triangles. Rays: one jittered camera ray per pixel (512×512) and random rays inside the box.

use std::hint::black_box;
use std::time::Duration;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use rayq::accel::RayQuery;
use rayq::mesh::MeshData;
use rayq::workload::{camera_rays, SplitMix64};
use rayq::{GridParams, MemoryBudget, Ray, TriMesh, UniformGrid};

fn scenes() -> Vec<(&'static str, MeshData)> {
    let dragon = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../shared/scenes/dragon_res2.obj"
    );
    let uniform = rayq::obj::load_obj(dragon)
        .map(|m| ("dragon_res2", m))
        .unwrap_or_else(|_| {
            (
                "sphereflake",
                rayq::procedural::by_name("sphereflake", 200_000).unwrap(),
            )
        });
    vec![
        uniform,
        (
            "stadium",
            rayq::procedural::by_name("stadium", 200_000).unwrap(),
        ),
    ]
}

fn random_rays(mesh: &TriMesh, n: usize, rng: &mut SplitMix64) -> Vec<Ray> {
    let b = mesh.bounds();
    (0..n)
        .map(|_| Ray::new(b.min + rng.next_vec3() * b.extent(), rng.unit_vector()))
        .collect()
}

fn bench(c: &mut Criterion) {
    for (name, data) in scenes() {
        let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
        let n = data.triangle_count() as u64;

        let mut group = c.benchmark_group(format!("grid_build/{name}"));
        group
            .throughput(Throughput::Elements(n))
            .sample_size(20)
            .measurement_time(Duration::from_secs(8));
        group.bench_function("validate+grid", |b| {
            b.iter(|| {
                let mut budget = MemoryBudget::new(0);
                let m = TriMesh::from_source(&data.as_source(), &mut budget).unwrap();
                black_box(UniformGrid::build(&m, &GridParams::DEFAULT, &mut budget).unwrap())
            })
        });
        group.bench_function("grid", |b| {
            b.iter(|| {
                black_box(
                    UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0))
                        .unwrap(),
                )
            })
        });
        group.finish();

        let grid =
            UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
        let mut rng = SplitMix64::new(7);
        let sets = [
            ("primary", camera_rays(&mesh.bounds(), 512, &mut rng)),
            ("random", random_rays(&mesh, 1 << 16, &mut rng)),
        ];
        let mut group = c.benchmark_group(format!("grid_rays/{name}"));
        group
            .sample_size(10)
            .measurement_time(Duration::from_secs(8));
        for (label, rays) in &sets {
            group.throughput(Throughput::Elements(rays.len() as u64));
            group.bench_with_input(BenchmarkId::from_parameter(label), rays, |b, rays| {
                b.iter(|| {
                    rays.iter()
                        .filter(|r| grid.intersect(&mesh, r).is_hit())
                        .count()
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
