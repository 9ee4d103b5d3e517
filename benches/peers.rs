//! rayq next to its peers: the same meshes and the same rays through rayq's grid and kd-tree, Embree 3
//! (`rtcIntersect1`, one thread, build quality LOW / MEDIUM / HIGH), obvhs (CWBVH, single thread) and
//! the `bvh` crate (binary SAH BVH, single thread).
//!
//!     apt-get install -y libembree-dev          # Embree 3.13 (Debian bookworm: 3.13.5)
//!     cargo bench --features peers --bench peers
//!
//! Scenes: teapot and stadium_teapot from `scenes/`, bunny and dragon_res2 from `../shared/scenes`
//! (skipped with a message when missing). Rays: one jittered camera ray per pixel (256×256) and one
//! diffuse bounce per primary ray that hits (hit points from rayq's grid), generated once per scene
//! and shared by every structure.
//!
//! Build time is "from the caller's indexed arrays to a structure that answers queries" for
//! everyone: rayq validates and copies the mesh and builds; Embree gets a new scene, a triangle
//! geometry whose buffers are filled from the arrays, and commits; obvhs converts the arrays to its
//! triangles, builds, and reorders the triangles into leaf order; the bvh crate converts them to its
//! shapes (one per triangle, with its box) and builds. Embree's device is created once.
//!
//! At the end a Markdown table of medians (build ms, primary and diffuse Mrays/s, and how many rays
//! disagree with rayq's grid on hit/miss and on the primitive hit) is printed; docs/peers.md holds
//! a copy. If `Structure::KdTree` cannot be built yet, its rows are skipped with a note.

use std::hint::black_box;
use std::path::Path;
use std::time::{Duration, Instant};

use criterion::{
    criterion_group, criterion_main, BenchmarkId, Criterion, SamplingMode, Throughput,
};

use rayq::triangle::PreparedRay;
use rayq::workload::{bounce_rays, camera_rays, SplitMix64};
use rayq::{BuildOptions, Calibration, Hit, MemoryBudget, Ray, Scene, Structure, TriMesh};

/// Camera rays per image side (256² = 65 536 primary rays).
const SIDE: usize = 256;
/// Criterion samples per benchmark; the summary is the median of these.
const SAMPLES: usize = 10;

#[path = "shared/peer_structures.rs"]
mod peer_structures;
use peer_structures::{embree3, Built, EmbreeDevice, Kind};

/// How `prims` (a peer's answers) differ from rayq's grid (`reference`) on the same rays.
#[derive(Clone, Copy, Default)]
struct Disagreement {
    /// One hits, the other misses.
    hit_miss: usize,
    /// Both hit, another primitive.
    prim: usize,
    /// Of `prim`: rayq's own triangle test hits the peer's triangle too, at a `t` within 1e-5
    /// (relative) of the grid's hit, i.e. a ray through a shared edge or vertex, or a duplicate
    /// triangle, answered by a different neighbour.
    prim_same_t: usize,
}

fn disagreements(mesh: &TriMesh, rays: &[Ray], reference: &[Hit], prims: &[u32]) -> Disagreement {
    let mut d = Disagreement::default();
    for ((ray, h), &p) in rays.iter().zip(reference).zip(prims) {
        if h.is_hit() != (p != Hit::INVALID_ID) {
            d.hit_miss += 1;
        } else if h.is_hit() && h.prim != p {
            d.prim += 1;
            let t = mesh
                .triangle(p)
                .and_then(|tri| PreparedRay::new(ray)?.intersect_triangle(tri[0], tri[1], tri[2]));
            if t.is_some_and(|(t, _, _)| (t - h.t).abs() <= 1e-5 * h.t.abs().max(t.abs())) {
                d.prim_same_t += 1;
            }
        }
    }
    d
}

fn scenes() -> Vec<(&'static str, String)> {
    let root = env!("CARGO_MANIFEST_DIR");
    vec![
        ("teapot", format!("{root}/scenes/teapot.obj")),
        (
            "stadium_teapot",
            format!("{root}/scenes/stadium_teapot.obj"),
        ),
        ("bunny", format!("{root}/../shared/scenes/bunny.obj")),
        (
            "dragon_res2",
            format!("{root}/../shared/scenes/dragon_res2.obj"),
        ),
    ]
}

fn median(v: &[f64]) -> Option<f64> {
    if v.is_empty() {
        return None;
    }
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let n = v.len();
    Some(if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    })
}

/// The median of the last `SAMPLES` per-iteration times criterion measured (earlier entries are its
/// warm-up calls).
fn sample_median(times: &[f64]) -> Option<f64> {
    if times.len() < SAMPLES {
        // `cargo bench -- --test` (one call) or a filter that skipped this benchmark.
        SHORT_RUN.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    median(&times[times.len().saturating_sub(SAMPLES)..])
}

/// Set when some summary figure comes from fewer than `SAMPLES` samples.
static SHORT_RUN: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Process CPU time (user + system, all threads) in seconds, from /proc/self/stat.
fn process_cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    let rest = &stat[stat.rfind(')')? + 2..];
    let fields: Vec<&str> = rest.split_whitespace().collect();
    // After the command name: field 3 is the state, so utime (14) and stime (15) are at 11 and 12.
    let ticks: u64 = fields.get(11)?.parse::<u64>().ok()? + fields.get(12)?.parse::<u64>().ok()?;
    Some(ticks as f64 / 100.0) // USER_HZ is 100 on Linux
}

struct Row {
    scene: &'static str,
    triangles: usize,
    label: String,
    build_s: Option<f64>,
    primary_s: Option<f64>,
    diffuse_s: Option<f64>,
    primary_rays: usize,
    diffuse_rays: usize,
    /// Against rayq's grid over primary + diffuse rays; None when not built.
    disagree: Option<Disagreement>,
    note: Option<String>,
}

fn bench(c: &mut Criterion) {
    let embree = match EmbreeDevice::new() {
        Ok(d) => {
            println!(
                "Embree {} (tasking system {}), device config \"threads=1\"",
                d.version(),
                d.property(embree3::RTC_DEVICE_PROPERTY_TASKING_SYSTEM)
            );
            Some(d)
        }
        Err(e) => {
            println!("Embree rows skipped: {e}");
            None
        }
    };
    let kinds = [
        Kind::Rayq(Structure::Grid),
        Kind::Rayq(Structure::KdTree),
        Kind::Embree(embree3::RTC_BUILD_QUALITY_LOW),
        Kind::Embree(embree3::RTC_BUILD_QUALITY_MEDIUM),
        Kind::Embree(embree3::RTC_BUILD_QUALITY_HIGH),
        Kind::Obvhs("fast_build", obvhs::BvhBuildParams::fast_build()),
        Kind::Obvhs("medium_build", obvhs::BvhBuildParams::medium_build()),
        Kind::Obvhs("slow_build", obvhs::BvhBuildParams::slow_build()),
        Kind::Bvh,
    ];
    let mut rows: Vec<Row> = Vec::new();
    let mut thread_check = None;

    for (name, path) in scenes() {
        if !Path::new(&path).exists() {
            println!("{name}: {path} not found, skipped");
            continue;
        }
        let data = match rayq::obj::load_obj(&path) {
            Ok(d) => d,
            Err(e) => {
                println!("{name}: {e}, skipped");
                continue;
            }
        };
        let tris = data.triangle_count();

        // The rays, once per scene: camera rays, then one bounce per hit found by rayq's grid.
        let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
        let grid = Scene::build(
            &data.as_source(),
            &BuildOptions {
                structure: Structure::Grid,
                ..BuildOptions::DEFAULT
            },
            Calibration::builtin(),
        )
        .unwrap();
        let mut rng = SplitMix64::new(0x5EED);
        let primary = camera_rays(&data.bounds(), SIDE, &mut rng);
        let hits: Vec<Hit> = primary.iter().map(|r| grid.intersect(r)).collect();
        let diffuse = bounce_rays(&mesh, &primary, &hits, &mut rng);
        let all_rays: Vec<Ray> = primary.iter().chain(&diffuse).copied().collect();
        let reference: Vec<Hit> = all_rays.iter().map(|r| grid.intersect(r)).collect();
        drop(grid);
        println!(
            "{name}: {tris} triangles, {} primary rays ({} hit), {} diffuse rays",
            primary.len(),
            hits.iter().filter(|h| h.is_hit()).count(),
            diffuse.len()
        );

        // Build every structure once (to skip the ones that cannot be built), then time builds.
        let mut built: Vec<(Kind, Built)> = Vec::new();
        let mut group = c.benchmark_group(format!("peers_build/{name}"));
        group
            .sampling_mode(SamplingMode::Flat)
            .sample_size(SAMPLES)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(2))
            .throughput(Throughput::Elements(tris as u64));
        for kind in kinds {
            let label = kind.label();
            let first = match kind.build(&data, embree.as_ref()) {
                Ok(b) => b,
                Err(e) => {
                    println!("{name} / {label}: not built ({e}); rows skipped");
                    rows.push(Row {
                        scene: name,
                        triangles: tris,
                        label,
                        build_s: None,
                        primary_s: None,
                        diffuse_s: None,
                        primary_rays: primary.len(),
                        diffuse_rays: diffuse.len(),
                        disagree: None,
                        note: Some(e),
                    });
                    continue;
                }
            };
            let mut times = Vec::new();
            group.bench_function(BenchmarkId::from_parameter(&label), |b| {
                b.iter_custom(|iters| {
                    let mut total = Duration::ZERO;
                    for _ in 0..iters {
                        let start = Instant::now();
                        let s = kind.build(&data, embree.as_ref());
                        total += start.elapsed();
                        drop(black_box(s));
                    }
                    times.push(total.as_secs_f64() / iters as f64);
                    total
                })
            });
            let prims: Vec<u32> = first.hits(&all_rays).iter().map(|h| h.0).collect();
            rows.push(Row {
                scene: name,
                triangles: tris,
                label,
                build_s: sample_median(&times),
                primary_s: None,
                diffuse_s: None,
                primary_rays: primary.len(),
                diffuse_rays: diffuse.len(),
                disagree: Some(disagreements(&mesh, &all_rays, &reference, &prims)),
                note: None,
            });
            built.push((kind, first));
        }
        group.finish();

        // Single-thread check on the most expensive Embree build of the last (largest) scene.
        if let (Some(device), true) = (embree.as_ref(), name == "dragon_res2") {
            let (cpu0, wall0) = (process_cpu_seconds(), Instant::now());
            for _ in 0..3 {
                drop(black_box(device.build(
                    &data,
                    embree3::RTC_BUILD_QUALITY_HIGH,
                    false,
                )));
            }
            let wall = wall0.elapsed().as_secs_f64();
            if let (Some(a), Some(b)) = (cpu0, process_cpu_seconds()) {
                thread_check = Some((b - a) / wall);
            }
        }

        for (set, rays) in [("primary", &primary), ("diffuse", &diffuse)] {
            let mut group = c.benchmark_group(format!("peers_{set}/{name}"));
            group
                .sampling_mode(SamplingMode::Flat)
                .sample_size(SAMPLES)
                .warm_up_time(Duration::from_millis(500))
                .measurement_time(Duration::from_secs(2))
                .throughput(Throughput::Elements(rays.len() as u64));
            for (kind, structure) in &built {
                let label = kind.label();
                let mut times = Vec::new();
                group.bench_function(BenchmarkId::from_parameter(&label), |b| {
                    b.iter_custom(|iters| {
                        let start = Instant::now();
                        for _ in 0..iters {
                            black_box(structure.count_hits(black_box(rays)));
                        }
                        let total = start.elapsed();
                        times.push(total.as_secs_f64() / iters as f64);
                        total
                    })
                });
                let m = sample_median(&times);
                if let Some(row) = rows
                    .iter_mut()
                    .find(|r| r.scene == name && r.label == label)
                {
                    if set == "primary" {
                        row.primary_s = m;
                    } else {
                        row.diffuse_s = m;
                    }
                }
            }
            group.finish();
        }
    }

    print_summary(&rows, thread_check);
}

fn print_summary(rows: &[Row], thread_check: Option<f64>) {
    let ms = |s: Option<f64>| s.map_or("—".to_string(), |s| format!("{:.2}", s * 1e3));
    let mrays = |s: Option<f64>, n: usize| {
        s.map_or("—".to_string(), |s| format!("{:.2}", n as f64 / s / 1e6))
    };
    println!();
    println!(
        "Medians of {SAMPLES} criterion samples. Disagreements with rayq's grid over primary + \
         diffuse rays: hit/miss / other prim (of which at the same t within 1e-5: shared edge, \
         vertex or duplicate triangle)."
    );
    println!();
    println!(
        "| scene | tris | structure | build ms | primary Mrays/s | diffuse Mrays/s | \
         disagreements: hit/miss / prim (same-t) |"
    );
    println!("|---|---:|---|---:|---:|---:|---|");
    for r in rows {
        let dis = match (r.disagree, &r.note) {
            (Some(d), _) => format!(
                "{} / {} ({} same-t) of {}",
                d.hit_miss,
                d.prim,
                d.prim_same_t,
                r.primary_rays + r.diffuse_rays
            ),
            (None, Some(note)) => format!("not measured yet ({note})"),
            (None, None) => "—".into(),
        };
        println!(
            "| {} | {} | {} | {} | {} | {} | {} |",
            r.scene,
            r.triangles,
            r.label,
            ms(r.build_s),
            mrays(r.primary_s, r.primary_rays),
            mrays(r.diffuse_s, r.diffuse_rays),
            dis
        );
    }
    if SHORT_RUN.load(std::sync::atomic::Ordering::Relaxed) {
        println!();
        println!(
            "Note: some figures come from fewer than {SAMPLES} samples (--test mode or a filter); \
             they are not medians."
        );
    }
    if let Some(ratio) = thread_check {
        println!();
        println!(
            "Embree HIGH builds of dragon_res2: process CPU time / wall time = {ratio:.2} \
             (≈1 means one thread)."
        );
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);
