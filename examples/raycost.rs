//! Per-ray cost of the two structures on one scene, for profiling: traces the workload's rays
//! (128² camera rays plus one diffuse bounce per hit) through the kd-tree or the grid, or times
//! both, or prints what a ray does in each.
//!
//!     cargo build --release --example raycost
//!     target/release/examples/raycost time 7 bunny hair-50k      # ns per ray, medians of 7 (with
//!                                                                 # --features peers, Embree MEDIUM's too)
//!     target/release/examples/raycost stats 1 bunny               # nodes, leaves, cells, tests
//!     target/release/examples/raycost check 1 bunny               # the selector's check after a kd build
//!     target/release/examples/raycost build 9 bunny               # mesh copy + grid build
//!     target/release/examples/raycost kdbuild 5 bunny             # kd-tree build and its shape
//!     GRID_DENSITY=1 target/release/examples/raycost time 5 bunny # another grid density (λ)
//!     RAYS=bounce target/release/examples/raycost time 5 bunny    # only the bounces (or RAYS=camera)
//!     RAYCOST_MIN=1 target/release/examples/raycost time 5 bunny  # the fastest repeat, not the median
//!     KD_CI=1 target/release/examples/raycost time 5 bunny        # other kd-tree costs (KD_BONUS, KD_EXACT, KD_DEPTH, KD_INDEXED)
//!     target/release/examples/raycost probe 3 bunny tetra-10k     # a kd-tree of every 16th triangle as a predictor
//!     target/release/examples/raycost floor 5                     # a query's fixed cost (one-triangle scene;
//!                                                                 # Embree beside it with --features peers)
//!     (`raycost::kd_build` and `raycost::grid_build` collect the builds' instructions)
//!     valgrind --tool=callgrind --toggle-collect='raycost::kd_trace' \
//!         target/release/examples/raycost kd 1 bunny              # instructions of kd-tree rays
//!
//! (`grid` and `raycost::grid_trace` for the grid.) A scene is a name in `../shared/scenes` or
//! `scenes` (without `.obj`), or a procedural one as `NAME-COUNT` (`hair-50k`, `stadium-1000k`).
//! The instructions per ray are callgrind's total over the printed number of rays.

use std::time::Instant;

#[path = "../benches/shared/floor.rs"]
mod floor;
#[cfg(feature = "peers")]
#[path = "../benches/shared/peer_structures.rs"]
mod peer_structures;

use rayq::accel::grid::GridWork;
use rayq::accel::kdtree::KdWork;
use rayq::accel::RayQuery;
use rayq::mesh::MeshData;
use rayq::workload::{bounce_rays, camera_rays, SplitMix64};
use rayq::{GridParams, KdTree, KdTreeParams, MemoryBudget, Ray, TriMesh, UniformGrid};

/// What `kdbuild` prints of a tree besides its build time.
#[derive(Clone, Copy, Default)]
struct TreeShape {
    work: u64,
    references: usize,
    nodes: usize,
    largest_leaf: usize,
    bytes: usize,
}

impl TreeShape {
    fn of(tree: &KdTree) -> TreeShape {
        TreeShape {
            work: tree.build_work(),
            references: tree.reference_count(),
            nodes: tree.node_count(),
            largest_leaf: tree.largest_leaf(),
            bytes: tree.memory_bytes(),
        }
    }
}

fn load(name: &str) -> Option<MeshData> {
    let root = env!("CARGO_MANIFEST_DIR");
    for dir in [format!("{root}/../shared/scenes"), format!("{root}/scenes")] {
        if let Ok(m) = rayq::obj::load_obj(format!("{dir}/{name}.obj")) {
            return Some(m);
        }
    }
    let (generator, count) = name.rsplit_once('-')?;
    let count = match count.strip_suffix('k') {
        Some(k) => k.parse::<usize>().ok()? * 1000,
        None => count.parse().ok()?,
    };
    rayq::procedural::by_name(generator, count)
}

#[inline(never)]
fn kd_trace(tree: &KdTree, mesh: &TriMesh, rays: &[Ray]) -> u32 {
    rays.iter().fold(0u32, |acc, r| {
        acc.wrapping_add(tree.intersect(mesh, r).prim)
    })
}

#[inline(never)]
fn grid_trace(grid: &UniformGrid, mesh: &TriMesh, rays: &[Ray]) -> u32 {
    rays.iter().fold(0u32, |acc, r| {
        acc.wrapping_add(grid.intersect(mesh, r).prim)
    })
}

#[inline(never)]
fn grid_build(data: &MeshData) -> (TriMesh, UniformGrid) {
    let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
    let grid = UniformGrid::build(&mesh, &grid_params(), &mut MemoryBudget::new(0)).unwrap();
    (mesh, grid)
}

#[inline(never)]
fn kd_build(mesh: &TriMesh) -> KdTree {
    KdTree::build(mesh, &kd_params(), &mut MemoryBudget::new(0)).unwrap()
}

/// The default kd-tree parameters, or those `KD_CI` (intersection cost), `KD_BONUS` (empty bonus),
/// `KD_EXACT` (exact split below), `KD_DEPTH` (depth limit) and `KD_INDEXED` (the indexed layout)
/// set (to try other trees without a rebuild).
fn kd_params() -> KdTreeParams {
    let var = |name: &str| std::env::var(name).ok().and_then(|v| v.parse::<f32>().ok());
    let mut p = KdTreeParams::DEFAULT;
    if let Some(x) = var("KD_CI") {
        p.intersection_cost = x;
    }
    if let Some(x) = var("KD_BONUS") {
        p.empty_bonus = x;
    }
    if let Some(x) = var("KD_EXACT") {
        p.exact_below = x as u32;
    }
    if let Some(x) = var("KD_DEPTH") {
        p.max_depth = x as u32;
    }
    if std::env::var("KD_INDEXED").is_ok() {
        p.layout = rayq::TriangleLayout::Indexed;
    }
    p
}

/// The default grid parameters, or the density `GRID_DENSITY` sets (to try other densities
/// without a rebuild).
fn grid_params() -> GridParams {
    let mut p = GridParams::DEFAULT;
    if let Some(d) = std::env::var("GRID_DENSITY")
        .ok()
        .and_then(|v| v.parse::<f32>().ok())
    {
        p.density = d;
    }
    p
}

/// The median, or the minimum when `RAYCOST_MIN` is set (on a machine whose noise only ever
/// adds time, the fastest repeat is the steadier figure).
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    if std::env::var("RAYCOST_MIN").is_ok() {
        return v[0];
    }
    v[v.len() / 2]
}

/// Every `k`-th triangle of `data` (the same vertices).
fn every_kth(data: &MeshData, k: usize) -> MeshData {
    MeshData {
        vertices: data.vertices.clone(),
        indices: data.indices.iter().step_by(k.max(1)).copied().collect(),
    }
}

/// What `probe` keeps of one scene for the summary: the measured kd/grid time per ray, the model's
/// estimate of it, the check's priced kd/grid work on the full and on the sampled structures, and
/// the kd-tree's build time with two predictors of it.
struct Probe {
    ray_ratio: [f64; 4],
    build_ms: f64,
    build_predictors: [f64; 4],
}

/// `|ln(prediction / truth)|` per scene, the prediction `c·x` with `c` fitted on the other scenes
/// (median ratio, leave-one-out).
fn loo_log_errors(x: &[f64], y: &[f64]) -> Vec<f64> {
    (0..x.len())
        .map(|i| {
            let others: Vec<f64> = (0..x.len())
                .filter(|&j| j != i)
                .map(|j| (y[j] / x[j]).ln())
                .collect();
            let c = if others.is_empty() {
                0.0
            } else {
                median(others)
            };
            (c + x[i].ln() - y[i].ln()).abs()
        })
        .collect()
}

/// `probe`: the selector's default sample rays through the full kd-tree and grid and through those
/// of every 16th triangle (at least 1 024), counted work priced as the check after a kd-tree
/// build prices it (`select::decision::priced_work`), against the measured time per ray of the
/// workload; and the kd-tree's build against `N·log2 N` and
/// against the sampled tree's build scaled by `N·log2 N / (N'·log2 N')`.
fn probe(data: &MeshData, mesh: &TriMesh, rays: &[Ray], reps: usize) -> Probe {
    use rayq::select::sample::{sample_grid, sample_kdtree, SampleParams};
    // The counted work priced as the check after a kd-tree build prices it, kd-tree over grid.
    let priced_ratio = |grid: &rayq::select::model::SceneFeatures,
                        kd: &rayq::select::model::SceneFeatures| {
        let (g, k) = rayq::select::decision::priced_work(
            rayq::Calibration::builtin(),
            grid,
            kd,
            &rayq::select::decision::CheckPrices::LIBRARY,
        );
        k / g
    };
    let nlogn = |n: usize| n as f64 * (n.max(2) as f64).log2();
    let timed_build = |m: &TriMesh| {
        let mut t = Vec::new();
        let mut tree = None;
        for _ in 0..reps {
            let t0 = Instant::now();
            tree = Some(kd_build(m));
            t.push(t0.elapsed().as_secs_f64() * 1e3);
        }
        (median(t), tree.unwrap())
    };
    let (build_ms, tree) = timed_build(mesh);
    let grid = UniformGrid::build(mesh, &grid_params(), &mut MemoryBudget::new(0)).unwrap();
    let (kd, gr) = time_both(&tree, &grid, mesh, rays, reps);
    let p = SampleParams::DEFAULT;
    let (g, k) = (
        sample_grid(&grid, mesh, None, &p),
        sample_kdtree(&tree, mesh, None, &p),
    );
    let est = rayq::Calibration::builtin().estimate(&g);
    let every = 16.min((mesh.len() / 1024).max(1));
    let sub_data = every_kth(data, every);
    let sub = TriMesh::from_source(&sub_data.as_source(), &mut MemoryBudget::new(0)).unwrap();
    let (sub_ms, sub_tree) = timed_build(&sub);
    let sub_grid = UniformGrid::build(&sub, &grid_params(), &mut MemoryBudget::new(0)).unwrap();
    let (sg, sk) = (
        sample_grid(&sub_grid, &sub, None, &p),
        sample_kdtree(&sub_tree, &sub, None, &p),
    );
    let ray_ratio = [
        kd / gr,
        est.kd_ray_seconds / est.grid_ray_seconds,
        priced_ratio(&g, &k),
        priced_ratio(&sg, &sk),
    ];
    let scaled_sub = sub_ms * nlogn(mesh.len()) / nlogn(sub.len());
    // What the library could use without a clock: the sampled tree's build work, scaled.
    let scaled_work = sub_tree.build_work() as f64 * nlogn(mesh.len()) / nlogn(sub.len());
    println!(
        "{:>8} tris, sampled {:>6} | kd/grid per ray: measured {:.2}, model {:.2}, priced work {:.2}, sampled priced work {:.2} | kd build {:7.2} ms, sampled {:6.3} ms ({:.1} %), scaled {:7.2}, work {:.3e} (sampled, scaled {:.3e})",
        mesh.len(),
        sub.len(),
        ray_ratio[0],
        ray_ratio[1],
        ray_ratio[2],
        ray_ratio[3],
        build_ms,
        sub_ms,
        100.0 * sub_ms / build_ms,
        scaled_sub,
        tree.build_work() as f64,
        scaled_work
    );
    Probe {
        ray_ratio,
        build_ms,
        build_predictors: [
            nlogn(mesh.len()),
            scaled_sub,
            tree.build_work() as f64,
            scaled_work,
        ],
    }
}

/// The medians (and largest) of `probe`'s errors over the scenes.
fn probe_summary(probes: &[Probe]) {
    let stats = |mut e: Vec<f64>| {
        e.sort_by(f64::total_cmp);
        (e[e.len() / 2], e[e.len() - 1])
    };
    let error = |i: usize, truth: usize| {
        stats(
            probes
                .iter()
                .map(|p| (p.ray_ratio[i] / p.ray_ratio[truth]).ln().abs())
                .collect(),
        )
    };
    let (m, w) = error(1, 0);
    println!("kd/grid time per ray from the model: median |ln error| {m:.3}, largest {w:.3}");
    let (m, w) = error(3, 2);
    println!(
        "the check's priced work, sampled against full structures: median |ln error| {m:.3}, largest {w:.3}"
    );
    // The check keeps the kd-tree when its priced work is below the grid's (ratio below 1).
    let agree = probes
        .iter()
        .filter(|p| (p.ray_ratio[2] < 1.0) == (p.ray_ratio[3] < 1.0))
        .count();
    let right = probes
        .iter()
        .filter(|p| (p.ray_ratio[2] < 1.0) == (p.ray_ratio[0] < 1.0))
        .count();
    println!(
        "the check's verdict: sampled structures agree with the full ones on {agree} of {n}; the full ones pick the faster on {right} of {n}",
        n = probes.len()
    );
    let y: Vec<f64> = probes.iter().map(|p| p.build_ms).collect();
    for (i, what) in [
        (0, "N log2 N"),
        (1, "the sampled tree's build, scaled"),
        (2, "the full tree's build work"),
        (3, "the sampled tree's build work, scaled"),
    ] {
        let x: Vec<f64> = probes.iter().map(|p| p.build_predictors[i]).collect();
        let (m, w) = stats(loo_log_errors(&x, &y));
        println!("kd build from {what} (leave-one-out): median |ln error| {m:.3}, largest {w:.3}");
    }
}

/// `floor`: what a query costs beside its walk (benches/shared/floor.rs), ns per ray (thread CPU
/// time, medians of `reps`), with Embree 3 MEDIUM beside it when built with `--features peers`.
fn floor(reps: usize) {
    for c in floor::measure(reps as u32) {
        print!(
            "{:>22}: kd {:6.1} ns/ray grid {:6.1} ns/ray",
            c.what, c.kd, c.grid
        );
        if let Some(e) = c.embree {
            print!(" Embree MEDIUM {e:6.1} ns/ray");
        }
        println!();
    }
}

/// Medians of `reps` alternated runs of `rays` through the kd-tree and the grid, in seconds.
fn time_both(
    tree: &KdTree,
    grid: &UniformGrid,
    mesh: &TriMesh,
    rays: &[Ray],
    reps: usize,
) -> (f64, f64) {
    let (mut kd, mut gr) = (Vec::new(), Vec::new());
    for _ in 0..reps {
        let t = Instant::now();
        std::hint::black_box(kd_trace(tree, mesh, rays));
        kd.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        std::hint::black_box(grid_trace(grid, mesh, rays));
        gr.push(t.elapsed().as_secs_f64());
    }
    (median(kd), median(gr))
}

/// Embree 3 MEDIUM's `rtcIntersect1` on `rays` (seconds, median of `reps`), or `None` when
/// Embree cannot build the scene.
#[cfg(feature = "peers")]
fn embree_medium_seconds(data: &MeshData, rays: &[Ray], reps: usize) -> Option<f64> {
    let device = peer_structures::EmbreeDevice::new().ok()?;
    let built = peer_structures::Kind::Embree(peer_structures::embree3::RTC_BUILD_QUALITY_MEDIUM)
        .build(data, Some(&device))
        .ok()?;
    let mut t = Vec::new();
    for _ in 0..reps {
        let t0 = Instant::now();
        std::hint::black_box(built.count_hits(rays));
        t.push(t0.elapsed().as_secs_f64());
    }
    Some(median(t))
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (Some(mode), Some(reps)) = (
        args.first(),
        args.get(1).and_then(|r| r.parse::<usize>().ok()),
    ) else {
        eprintln!(
            "usage: raycost kd|grid|time|stats|check|probe|floor|build|cold|kdbuild REPEATS SCENE..."
        );
        std::process::exit(2);
    };
    let reps = reps.max(1);
    if mode == "floor" {
        floor(reps);
        return;
    }
    let mut probes = Vec::new();
    for name in &args[2..] {
        let Some(data) = load(name) else {
            eprintln!("{name}: no such scene");
            std::process::exit(2);
        };
        if mode == "cold" {
            // As the evaluation times it: thread CPU time, each build's memory fresh (the previous
            // grid is dropped only after the next is built).
            let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
            let (t, grid) = rayq::select::measure::time_ns(reps as u32, || {
                UniformGrid::build(&mesh, &grid_params(), &mut MemoryBudget::new(0))
            });
            let n = mesh.len() as f64;
            println!(
                "{name:>16} N {n:>8} grid build (cold, CPU) median {:6.2} ms min {:6.2} max {:6.2} = {:5.1} Mtri/s, {} bytes",
                t.median * 1e-6,
                t.min * 1e-6,
                t.max * 1e-6,
                n / t.median * 1e3,
                grid.unwrap().memory_bytes()
            );
            continue;
        }
        if mode == "build" || mode == "gridbuild" {
            let mut times = (Vec::new(), Vec::new());
            let mut refs = (0, 0, 0);
            for _ in 0..reps {
                let t = Instant::now();
                let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0));
                times.0.push(t.elapsed().as_secs_f64());
                drop(std::hint::black_box(mesh));
                let t = Instant::now();
                let built = grid_build(&data);
                times.1.push(t.elapsed().as_secs_f64());
                refs = (
                    built.1.reference_count(),
                    built.1.cell_count(),
                    built.1.memory_bytes(),
                );
                drop(std::hint::black_box(built));
            }
            let n = data.triangle_count() as f64;
            let (mesh, total) = (median(times.0), median(times.1));
            println!(
                "{name:>16} N {n:>8} mesh {:6.2} ms grid total {:6.2} ms = {:5.1} Mtri/s ({:5.1} ns/tri, mesh {:4.1}) refs/tri {:.2} cells {} bytes/tri {:.0}",
                mesh * 1e3,
                total * 1e3,
                n / total * 1e-6,
                total * 1e9 / n,
                mesh * 1e9 / n,
                refs.0 as f64 / n,
                refs.1,
                refs.2 as f64 / n
            );
            continue;
        }
        let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
        if mode == "kdbuild" {
            let mut t = Vec::new();
            let mut last = None;
            for _ in 0..reps {
                let t0 = Instant::now();
                let tree = kd_build(&mesh);
                t.push(t0.elapsed().as_secs_f64());
                last = Some(TreeShape::of(&tree));
                drop(std::hint::black_box(tree));
            }
            let shape = last.unwrap_or_default();
            let n = mesh.len() as f64;
            println!(
                "{name:>16} N {:>8} kd build {:8.2} ms work/tri {:5.1} refs/tri {:4.2} nodes {} largest leaf {} bytes/tri {:.0}",
                mesh.len(),
                median(t) * 1e3,
                shape.work as f64 / n,
                shape.references as f64 / n,
                shape.nodes,
                shape.largest_leaf,
                shape.bytes as f64 / n
            );
            continue;
        }
        let tree = kd_build(&mesh);
        let grid = UniformGrid::build(&mesh, &grid_params(), &mut MemoryBudget::new(0)).unwrap();
        let mut rng = SplitMix64::new(7);
        let mut rays = camera_rays(&mesh.bounds(), 128, &mut rng);
        let hits: Vec<_> = rays.iter().map(|r| tree.intersect(&mesh, r)).collect();
        let bounces = bounce_rays(&mesh, &rays, &hits, &mut rng);
        match std::env::var("RAYS").as_deref() {
            Ok("camera") => {}
            Ok("bounce") => rays = bounces,
            _ => rays.extend(bounces),
        }
        let n = rays.len() as f64;
        if mode == "probe" {
            print!("{name:>16} ");
            probes.push(probe(&data, &mesh, &rays, reps));
            continue;
        }
        match mode.as_str() {
            "kd" => println!(
                "{name} {} rays {}",
                rays.len(),
                kd_trace(&tree, &mesh, &rays)
            ),
            "grid" => println!(
                "{name} {} rays {}",
                rays.len(),
                grid_trace(&grid, &mesh, &rays)
            ),
            "time" => {
                let (kd, gr) = time_both(&tree, &grid, &mesh, &rays, reps);
                print!(
                    "{name:>16} N {:>8} kd {:7.1} ns/ray grid {:7.1} ns/ray",
                    mesh.len(),
                    kd * 1e9 / n,
                    gr * 1e9 / n
                );
                #[cfg(feature = "peers")]
                if let Some(e) = embree_medium_seconds(&data, &rays, reps) {
                    print!(" Embree MEDIUM {:7.1} ns/ray", e * 1e9 / n);
                }
                println!();
            }
            "check" => {
                use rayq::select::decision::kd_tree_confirmed;
                use rayq::select::sample::{sample_grid, sample_kdtree, SampleParams};
                let p = SampleParams::DEFAULT;
                let g = sample_grid(&grid, &mesh, None, &p);
                let k = sample_kdtree(&tree, &mesh, None, &p);
                println!(
                    "{name:>16} samples {} | grid cells {:.1} tests {:.1} | kd nodes {:.1} tests {:.1} | check keeps kd: {}",
                    g.rays,
                    g.cells_per_ray(),
                    g.tests_per_ray(),
                    k.cells_per_ray(),
                    k.tests_per_ray(),
                    kd_tree_confirmed(rayq::Calibration::builtin(), &g, &k)
                );
            }
            "stats" => {
                let (mut kw, mut gw) = (KdWork::default(), GridWork::default());
                let mut hits = 0u32;
                for r in &rays {
                    tree.intersect_counted(&mesh, r, &mut kw);
                    hits += u32::from(grid.intersect_counted(&mesh, r, &mut gw).is_hit());
                }
                println!(
                    "{name:>16} hits {:.3} kd nodes {:.1} leaves {:.1} tests {:.1} (depth {}, {} leaves) | grid cells {:.1} tests {:.1} (largest cell {}, nested grids {})",
                    f64::from(hits) / n,
                    f64::from(kw.nodes) / n,
                    f64::from(kw.leaves) / n,
                    f64::from(kw.tests) / n,
                    tree.depth(),
                    tree.leaf_count(),
                    f64::from(gw.cells) / n,
                    f64::from(gw.tests) / n,
                    grid.largest_cell(),
                    grid.nested_count()
                );
            }
            _ => {
                eprintln!(
                    "unknown mode {mode}: kd, grid, time, stats, check, probe, build, cold or kdbuild"
                );
                std::process::exit(2);
            }
        }
    }
    if !probes.is_empty() {
        probe_summary(&probes);
    }
}
