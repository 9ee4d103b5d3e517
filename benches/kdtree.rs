//! kd-tree against grid, same scenes and rays: build time and closest-hit rays/s on primary and
//! diffuse-bounce rays; then the kd-tree build's scaling over 10³..10⁶ triangles.
//!
//!     cargo bench --bench kdtree
//!
//! Scenes: bunny (69k, scanned, uniform) and sibenik (73k, clustered interior) from ../shared/scenes
//! when present (procedural sphereflake and rings otherwise), and the bundled stadium_teapot (18k,
//! teapot in a stadium). Rays: 256×256 jittered camera rays, then one diffuse bounce per hit.
//! The scaling part prints median build time / (N log2 N) for procedural sphereflakes.

use std::hint::black_box;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use rayq::accel::RayQuery;
use rayq::mesh::MeshData;
use rayq::workload::{bounce_rays, camera_rays, SplitMix64};
use rayq::{GridParams, Hit, KdTree, KdTreeParams, MemoryBudget, Ray, TriMesh, UniformGrid};

fn shared_or(name: &str, fallback: &str, n: usize) -> (String, MeshData) {
    let path = format!("{}/../shared/scenes/{name}.obj", env!("CARGO_MANIFEST_DIR"));
    match rayq::obj::load_obj(&path) {
        Ok(m) => (name.to_string(), m),
        Err(_) => (
            fallback.to_string(),
            rayq::procedural::by_name(fallback, n).expect("known generator"),
        ),
    }
}

fn scenes() -> Vec<(String, MeshData)> {
    let stadium = format!("{}/scenes/stadium_teapot.obj", env!("CARGO_MANIFEST_DIR"));
    vec![
        shared_or("bunny", "sphereflake", 70_000),
        shared_or("sibenik", "rings", 70_000),
        (
            "stadium_teapot".to_string(),
            rayq::obj::load_obj(stadium).expect("bundled scene"),
        ),
    ]
}

fn mesh_of(data: &MeshData) -> TriMesh {
    TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap()
}

fn trace(accel: &dyn RayQuery, mesh: &TriMesh, rays: &[Ray]) -> u32 {
    let mut acc = 0u32;
    for r in rays {
        acc = acc.wrapping_add(accel.intersect(mesh, r).prim);
    }
    acc
}

fn bench(c: &mut Criterion) {
    for (name, data) in scenes() {
        let mesh = mesh_of(&data);
        let n = mesh.len() as u64;
        let grid =
            UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
        let tree = KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();

        let mut group = c.benchmark_group(format!("build/{name}"));
        group
            .throughput(Throughput::Elements(n))
            .sample_size(10)
            .measurement_time(Duration::from_secs(6));
        group.bench_function("grid", |b| {
            b.iter(|| {
                UniformGrid::build(
                    black_box(&mesh),
                    &GridParams::DEFAULT,
                    &mut MemoryBudget::new(0),
                )
                .unwrap()
            })
        });
        group.bench_function("kdtree", |b| {
            b.iter(|| {
                KdTree::build(
                    black_box(&mesh),
                    &KdTreeParams::DEFAULT,
                    &mut MemoryBudget::new(0),
                )
                .unwrap()
            })
        });
        group.finish();

        let mut rng = SplitMix64::new(7);
        let primary = camera_rays(&mesh.bounds(), 256, &mut rng);
        let hits: Vec<Hit> = primary.iter().map(|r| tree.intersect(&mesh, r)).collect();
        let diffuse = bounce_rays(&mesh, &primary, &hits, &mut rng);
        for (kind, rays) in [("primary", &primary), ("diffuse", &diffuse)] {
            let mut group = c.benchmark_group(format!("rays/{name}/{kind}"));
            group
                .throughput(Throughput::Elements(rays.len() as u64))
                .sample_size(10)
                .measurement_time(Duration::from_secs(5));
            group.bench_function("grid", |b| b.iter(|| trace(&grid, &mesh, rays)));
            group.bench_function("kdtree", |b| b.iter(|| trace(&tree, &mesh, rays)));
            group.finish();
        }
    }
}

/// Median kd-tree build time over procedural sphereflakes of 10³..10⁶ triangles, per N log2 N.
fn scaling(_: &mut Criterion) {
    println!("\nkd-tree build scaling (procedural sphereflake, median of 3):");
    println!(
        "{:>9} {:>11} {:>16} {:>9}",
        "N", "build ms", "ns / (N log2 N)", "refs/tri"
    );
    for target in [1_000usize, 10_000, 100_000, 1_000_000] {
        let data = rayq::procedural::by_name("sphereflake", target).unwrap();
        let mesh = mesh_of(&data);
        let mut times = Vec::new();
        let mut refs = 0.0;
        for _ in 0..3 {
            let t = Instant::now();
            let tree =
                KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
            times.push(t.elapsed().as_secs_f64());
            refs = tree.reference_count() as f64 / mesh.len() as f64;
        }
        times.sort_by(f64::total_cmp);
        let n = mesh.len() as f64;
        println!(
            "{:>9} {:>11.2} {:>16.2} {:>9.2}",
            mesh.len(),
            times[1] * 1e3,
            times[1] * 1e9 / (n * n.log2()),
            refs
        );
    }
}

criterion_group!(benches, bench, scaling);
criterion_main!(benches);
