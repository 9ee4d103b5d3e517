//! The evaluation: reproduces the paper's experiment (Hapala, Karlík, Havran 2011) on this machine
//! and writes `docs/evaluation.md` with its charts (SVG) into `docs/`.
//!
//!     cargo run --release --example evaluate                 # full scene set (~10 minutes)
//!     cargo run --release --example evaluate -- --quick      # bundled scenes and small procedural ones
//!     cargo run --release --example evaluate --features peers    # + Embree 3, obvhs, bvh in the same run
//!     cargo run --release --example evaluate -- --interior   # only the interior-camera case, printed
//!
//! For every scene: both structures are built and the path-tracer-like workload (camera rays plus
//! one diffuse bounce per hit) is traced through each, repeated, medians kept and the spread
//! reported; the measured W* follows. The estimated W* is what the selector would say at run time
//! (its sample rays through the grid, costed by a calibration) with the calibration fitted on the
//! other scenes: leave-one-out, and 4-fold as in the paper. Then, per ray budget R = 10³..10⁸: the
//! total time of grid only, kd-tree only, the selector with R known, the selector with R unknown
//! (online switch), and the peers; the regret against the oracle (the better fixed choice knowing R).

mod accuracy;
#[path = "../../benches/shared/floor.rs"]
mod floor;
mod interior;
#[cfg(feature = "peers")]
#[path = "../../benches/shared/peer_structures.rs"]
mod peer_structures;
mod svg;

use std::fmt::Write as _;
use std::path::PathBuf;

use rayq::mesh::MeshData;
use rayq::select::calibration::BUILTIN_VARIANT;
use rayq::select::clock::Clock;
use rayq::select::decision::{
    kd_tree_confirmed, kd_tree_confirmed_at, kd_tree_confirmed_timed, kd_tree_work_limit,
    CheckPrices, CostEstimate, TRIAL_SHARE,
};
use rayq::select::fit::{fit_check_prices, CheckObservation, Observation};
use rayq::select::measure::{
    median_ns, observe_rays, thread_seconds, trace, workload, MeasureParams, Spread,
};
use rayq::select::model::Part;
use rayq::select::model::SceneFeatures;
use rayq::select::sample::{
    sample_grid, sample_kdtree, time_samples, RaySource, SampleParams, UNKNOWN_BUDGET_SIDE,
};
use rayq::select::validate::{
    best_variant, cross_validated_break_even, cross_validated_errors,
    cross_validated_estimates_for, median, relative_error, GridCost, VARIANTS,
};
#[cfg(feature = "peers")]
use rayq::Ray;
use rayq::{GridParams, Hit, KdTree, KdTreeParams, MemoryBudget, TriMesh, UniformGrid};
use svg::{Chart, Mark, Series};

/// Camera sides of the selector's sample rays tried for the speed/accuracy chart.
const SAMPLE_SIDES: [u32; 8] = [2, 4, 8, 12, 16, 24, 32, 48];
/// Ray budgets, half decades from 10³ to 10⁸.
fn budgets() -> Vec<f64> {
    (0..=10).map(|k| 10f64.powf(3.0 + 0.5 * k as f64)).collect()
}

struct Args {
    quick: bool,
    out: PathBuf,
}

fn parse() -> Args {
    let mut a = Args {
        quick: false,
        out: PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/docs")),
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--quick" => a.quick = true,
            "--interior" => {
                // Issue 14's interior case alone, printed (docs/evaluation.md has it in full).
                print!("{}", interior::section(5).unwrap_or_default());
                std::process::exit(0);
            }
            "--out" => a.out = it.next().map(PathBuf::from).unwrap_or(a.out),
            _ => {
                eprintln!("usage: evaluate [--quick] [--out DIR] | --interior");
                std::process::exit(2);
            }
        }
    }
    a
}

/// A scene of the set: name, group (for the charts), mesh.
struct SceneSpec {
    name: String,
    group: &'static str,
    data: MeshData,
}

fn group_of(name: &str) -> &'static str {
    match name {
        n if n.contains("stadium") || n == "spd_teapot" => "stadium",
        "bunny" | "dragon_res2" | "dragon_res3" | "horse" | "nefertiti" | "armadillo_29k" => {
            "scanned"
        }
        "fandisk" | "engine_2cyl" | "rocker_arm" | "f15" | "xwing" | "teapot" => "CAD",
        "sibenik" | "munich" | "mountain" => "architecture & terrain",
        _ => "procedural",
    }
}

fn scene_set(quick: bool) -> Vec<SceneSpec> {
    let root = env!("CARGO_MANIFEST_DIR");
    let mut files: Vec<PathBuf> = Vec::new();
    let dirs = if quick {
        vec![format!("{root}/scenes")]
    } else {
        vec![format!("{root}/../shared/scenes")]
    };
    for d in dirs {
        if let Ok(rd) = std::fs::read_dir(&d) {
            files.extend(
                rd.filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| p.extension().is_some_and(|e| e == "obj")),
            );
        }
    }
    if !quick && files.is_empty() {
        eprintln!("../shared/scenes not found; using scenes/");
        return scene_set(true);
    }
    files.sort();
    let mut v: Vec<SceneSpec> = files
        .iter()
        .filter_map(|p| {
            let name = p.file_stem()?.to_string_lossy().into_owned();
            match rayq::obj::load_obj(p) {
                Ok(data) => Some(SceneSpec {
                    group: group_of(&name),
                    name,
                    data,
                }),
                Err(e) => {
                    eprintln!("skipping {}: {e}", p.display());
                    None
                }
            }
        })
        .collect();
    let procedural: &[(&str, usize)] = if quick {
        &[
            ("sphereflake", 1_000),
            ("sphereflake", 10_000),
            ("stadium", 10_000),
            ("soup", 2_000),
        ]
    } else {
        &[
            ("sphereflake", 1_000),
            ("sphereflake", 10_000),
            ("sphereflake", 100_000),
            ("sphereflake", 1_000_000),
            ("stadium", 10_000),
            ("stadium", 1_000_000),
            ("mount", 100_000),
            ("rings", 100_000),
            ("gears", 10_000),
            ("tetra", 10_000),
            ("soup", 10_000),
            ("slivers", 2_000),
            ("hair", 50_000),
        ]
    };
    for &(name, n) in procedural {
        if let Some(data) = rayq::procedural::by_name(name, n) {
            let label = if n >= 1_000_000 {
                format!("{name}-{}M", n / 1_000_000)
            } else {
                format!("{name}-{}k", n / 1000)
            };
            v.push(SceneSpec {
                group: group_of(&label),
                name: label,
                data,
            });
        }
    }
    v
}

/// A peer's build and per-ray time (ns) and its hit accuracy against the exact answers.
struct PeerResult {
    label: String,
    build_ns: f64,
    ray_ns: f64,
    accuracy: Option<accuracy::Accuracy>,
}

/// What the evaluation measured on one scene.
struct Measured {
    name: String,
    group: &'static str,
    triangles: usize,
    obs: Observation,
    spread: Spread,
    /// Sample features and sampling time (ns) for each of `SAMPLE_SIDES`.
    samples: Vec<(SceneFeatures, f64)>,
    /// The same sample rays through the kd-tree (for the selector's check after building it).
    kd_samples: Vec<(SceneFeatures, f64)>,
    /// When the selector's kd-tree build stops at its work limit (`kd_tree_work_limit`): the
    /// seconds it took until then (median of the repeats). None: it finishes.
    abandoned_s: Option<f64>,
    /// rayq's accuracy against the exact answers, grid and kd-tree (None: not checked).
    rayq_accuracy: Option<[accuracy::Accuracy; 2]>,
    peers: Vec<PeerResult>,
    /// The workload's camera rays and its bounces timed apart: (kd-tree, grid) ns per ray for
    /// each kind (medians of the repeats, thread CPU time); `None` where a kind has no rays.
    by_kind: [Option<(f64, f64)>; 2],
    /// Per sample side, the timed check's two passes: (grid, kd-tree) ns for all the samples.
    timed_samples: Vec<(f64, f64)>,
    /// The check on a sixteenth of the workload's bounces passed as the caller's samples (`None`
    /// where nothing is hit).
    bounce_check: Option<BounceCheck>,
}

/// Scene `m`'s check on bounce samples, and its observation with the bounces' measured times per
/// ray in place of the workload's (`None` where it has no bounces).
fn on_bounces(m: &Measured) -> Option<(&BounceCheck, Observation)> {
    let (b, (kd, grid)) = (m.bounce_check.as_ref()?, m.by_kind[1]?);
    let o = Observation {
        grid_ray_ns: grid,
        kd_ray_ns: kd,
        ..m.obs
    };
    Some((b, o))
}

/// AUTO / oracle over scenes × budgets: every value, and the worst with where it was.
#[derive(Default)]
struct Regrets {
    all: Vec<f64>,
    worst: (f64, String),
}

impl Regrets {
    fn add(&mut self, x: f64, scene: &str, r: f64) {
        self.all.push(x);
        if x > self.worst.0 {
            self.worst = (x, format!("{scene} at {r:.0e}"));
        }
    }

    /// "geometric mean M and worst W (where)".
    fn summary(&self) -> String {
        format!(
            "geometric mean {:.3} and worst {:.3} ({})",
            geomean(&self.all),
            self.worst.0,
            self.worst.1
        )
    }
}

/// The check after a kd-tree build on bounce samples: both structures' counts, their plain passes'
/// times and their counted passes' (the sampling's and the priced check's cost), ns.
struct BounceCheck {
    grid: SceneFeatures,
    kd: SceneFeatures,
    grid_ns: f64,
    kd_ns: f64,
    grid_counted_ns: f64,
    kd_counted_ns: f64,
}

/// The accuracy check: its rays, their exact answers, and whether the mesh is closed.
struct Check {
    rays: accuracy::CheckRays,
    want: Vec<Hit>,
    closed: bool,
}

#[cfg(feature = "peers")]
fn peers(
    data: &MeshData,
    mesh: &TriMesh,
    rays: &[Ray],
    check: Option<&Check>,
    repeats: u32,
    device: Option<&peer_structures::EmbreeDevice>,
) -> Vec<PeerResult> {
    use peer_structures::{embree3, Kind};
    use rayq::select::measure::median_ns;
    let kinds = [
        Kind::Embree(embree3::RTC_BUILD_QUALITY_LOW),
        Kind::Embree(embree3::RTC_BUILD_QUALITY_MEDIUM),
        Kind::Embree(embree3::RTC_BUILD_QUALITY_HIGH),
        Kind::EmbreeRobust(embree3::RTC_BUILD_QUALITY_MEDIUM),
        Kind::Obvhs("medium_build", obvhs::BvhBuildParams::medium_build()),
        Kind::Bvh,
    ];
    let mut out = Vec::new();
    for kind in kinds {
        let (build_ns, built) = median_ns(repeats, || kind.build(data, device));
        let Ok(built) = built else { continue };
        let (t, _) = median_ns(repeats, || built.count_hits(rays));
        let accuracy = check
            .map(|c| accuracy::judge(mesh, &c.rays, &c.want, &built.hits(&c.rays.rays), c.closed));
        out.push(PeerResult {
            label: kind.label(),
            build_ns,
            ray_ns: t / rays.len().max(1) as f64,
            accuracy,
        });
    }
    out
}

fn measure_scene(spec: &SceneSpec, params: &MeasureParams, quick: bool) -> Option<Measured> {
    let mesh = TriMesh::from_source(&spec.data.as_source(), &mut MemoryBudget::new(0)).ok()?;
    let rays = workload(&mesh, params.workload_side, params.seed);
    let (obs, spread) = observe_rays(&mesh, &rays, params).ok()?;
    let grid = UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).ok()?;
    let tree = KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).ok()?;
    // The workload is its camera rays (side²) followed by their bounces.
    let camera = (params.workload_side as usize).pow(2).min(rays.len());
    let per_ray_ns = |q: &dyn rayq::RayQuery, part: &[rayq::Ray]| {
        median_ns(params.repeats, || trace(q, &mesh, part)).0 / part.len() as f64
    };
    let by_kind = [&rays[..camera], &rays[camera..]]
        .map(|part| (!part.is_empty()).then(|| (per_ray_ns(&tree, part), per_ray_ns(&grid, part))));
    // Per sample side, as a scene does it: the grid's counted pass (the estimate's features) and
    // right after it the grid's timed pass (what a scene with a clock times before a kd-tree
    // build), then the kd-tree's counted pass (the priced check) and its timed pass (the timed
    // check). The counted passes are timed too (the sampling's and the priced check's cost).
    let clock = Clock::THREAD;
    let (mut samples, mut kd_samples, mut timed_samples) = (Vec::new(), Vec::new(), Vec::new());
    for &side in &SAMPLE_SIDES {
        let p = SampleParams {
            camera_side: side,
            ..SampleParams::DEFAULT
        };
        let (grid_counted, g) = clock.time(|| sample_grid(&grid, &mesh, None, &p));
        let grid_ns = time_samples(&grid, &mesh, None, &p, &clock);
        let (kd_counted, k) = clock.time(|| sample_kdtree(&tree, &mesh, None, &p));
        let kd_ns = time_samples(&tree, &mesh, None, &p, &clock);
        samples.push((g, grid_counted as f64));
        kd_samples.push((k, kd_counted as f64));
        timed_samples.push((grid_ns as f64, kd_ns as f64));
    }
    // A renderer that passes its own diffuse bounces as samples: every 16th of the workload's.
    let bounce_samples: Vec<rayq::Ray> = rays[camera..].iter().step_by(16).copied().collect();
    let bounce_check = (!bounce_samples.is_empty()).then(|| {
        let src: Option<&dyn RaySource> = Some(&bounce_samples);
        let p = SampleParams::DEFAULT;
        let (grid_counted, g) = clock.time(|| sample_grid(&grid, &mesh, src, &p));
        let grid_ns = time_samples(&grid, &mesh, src, &p, &clock);
        let (kd_counted, k) = clock.time(|| sample_kdtree(&tree, &mesh, src, &p));
        let kd_ns = time_samples(&tree, &mesh, src, &p, &clock);
        BounceCheck {
            grid: g,
            kd: k,
            grid_ns: grid_ns as f64,
            kd_ns: kd_ns as f64,
            grid_counted_ns: grid_counted as f64,
            kd_counted_ns: kd_counted as f64,
        }
    });
    let limit = kd_tree_work_limit(mesh.len() - mesh.degenerate_count());
    let abandoned_s = (tree.build_work() > limit).then(|| {
        let mut times: Vec<f64> = (0..params.repeats.max(1))
            .map(|_| {
                let t = thread_seconds();
                let none = KdTree::build_within(
                    &mesh,
                    &KdTreeParams::DEFAULT,
                    &mut MemoryBudget::new(0),
                    limit,
                );
                let dt = thread_seconds() - t;
                debug_assert!(matches!(none, Ok(None)));
                dt
            })
            .collect();
        times.sort_by(f64::total_cmp);
        times[times.len() / 2]
    });
    // Accuracy against the exact answers (brute force, so only where it is affordable).
    let limit = if quick { 20_000 } else { 130_000 };
    let check = (mesh.len() <= limit).then(|| {
        let (mixed, aimed) = if quick { (500, 300) } else { (1500, 600) };
        let rays = accuracy::CheckRays::new(&mesh, &rays, mixed, aimed, params.seed ^ 0xacc);
        let want = accuracy::reference(&mesh, &rays.rays);
        Check {
            rays,
            want,
            closed: accuracy::is_closed(&mesh),
        }
    });
    let rayq_accuracy = check.as_ref().map(|c| {
        let judge = |s: &dyn rayq::RayQuery| {
            let answers: Vec<(u32, f32)> = c
                .rays
                .rays
                .iter()
                .map(|r| {
                    let h = s.intersect(&mesh, r);
                    (h.prim, h.t)
                })
                .collect();
            accuracy::judge(&mesh, &c.rays, &c.want, &answers, c.closed)
        };
        [judge(&grid), judge(&tree)]
    });
    #[cfg(feature = "peers")]
    let peers = {
        thread_local! {
            static DEVICE: Option<peer_structures::EmbreeDevice> = peer_structures::EmbreeDevice::new().ok();
        }
        DEVICE.with(|d| {
            peers(
                &spec.data,
                &mesh,
                &rays,
                check.as_ref(),
                params.repeats,
                d.as_ref(),
            )
        })
    };
    #[cfg(not(feature = "peers"))]
    let peers = Vec::new();
    Some(Measured {
        name: spec.name.clone(),
        group: spec.group,
        triangles: mesh.len(),
        obs,
        spread,
        samples,
        kd_samples,
        abandoned_s,
        rayq_accuracy,
        peers,
        by_kind,
        timed_samples,
        bounce_check,
    })
}

/// Totals (seconds) of the strategies for `r` rays on a measured scene.
struct Totals {
    grid: f64,
    kd: f64,
    auto_known: f64,
    auto_unknown: f64,
    oracle: f64,
}

/// What the selector sees and pays on a scene for one budget: its estimates, the time of its
/// sample rays on the grid, whether the kd-tree passes the check after it is built, and the time of
/// the sample rays on the kd-tree (the check's cost); or, when the build stops at its work limit,
/// the time until then (the grid stays, rebuilt).
#[derive(Clone, Copy)]
struct Selector {
    estimate: CostEstimate,
    sample_s: f64,
    confirmed: bool,
    check_s: f64,
    abandoned_s: Option<f64>,
}

/// The total of choosing the kd-tree after `first` rays on the grid: its build, the check, and the
/// rest of the rays on whichever structure the check leaves. With a known budget (`released`) the
/// library releases the grid before the build and builds it again when the tree is abandoned or
/// dropped by the check (src/scene/choose.rs); the online switch keeps the grid while it builds.
fn after_switch(o: &Observation, s: &Selector, first: f64, r: f64, released: bool) -> f64 {
    let (b, tg, tk) = (
        o.kd_build_ns * 1e-9,
        o.grid_ray_ns * 1e-9,
        o.kd_ray_ns * 1e-9,
    );
    let rebuild = if released {
        o.grid_build_ns * 1e-9
    } else {
        0.0
    };
    if let Some(abandoned) = s.abandoned_s {
        // Stopped at the work limit: the rest on the grid.
        return first * tg + abandoned + rebuild + (r - first) * tg;
    }
    if s.confirmed {
        first * tg + b + s.check_s + (r - first) * tk
    } else {
        first * tg + b + s.check_s + rebuild + (r - first) * tg
    }
}

/// The workload's two kinds of rays timed apart on each structure: which structure is the faster
/// per ray depends on the mix (docs/performance.md, "Stop 42"), and the workload has one bounce per
/// camera hit, where a path tracer's rays are mostly bounces.
fn kinds_section(md: &mut String, results: &[Measured]) {
    let _ = writeln!(
        md,
        "## Camera rays and bounces apart\n\nThe workload's camera rays (from outside the box) and \
         its diffuse bounces (from the hits) traced apart, ns per ray (medians of the repeats), \
         and the kd-tree's time over the grid's for each kind:\n\n| scene | camera: kd-tree / grid \
         | kd / grid | bounce: kd-tree / grid | kd / grid |\n|---|---:|---:|---:|---:|"
    );
    let mut ratios = [Vec::new(), Vec::new()];
    for m in results {
        let [Some((kc, gc)), Some((kb, gb))] = m.by_kind else {
            continue;
        };
        ratios[0].push(kc / gc);
        ratios[1].push(kb / gb);
        let _ = writeln!(
            md,
            "| {} | {kc:.0} / {gc:.0} | {:.2} | {kb:.0} / {gb:.0} | {:.2} |",
            m.name,
            kc / gc,
            kb / gb
        );
    }
    if !ratios[0].is_empty() {
        let faster = |v: &[f64]| v.iter().filter(|&&r| r < 1.0).count();
        let _ = writeln!(
            md,
            "\nkd-tree over grid, geometric mean: camera rays {:.3} (the kd-tree the faster on {} of \
             {}), bounces {:.3} ({} of {}).\n",
            geomean(&ratios[0]),
            faster(&ratios[0]),
            ratios[0].len(),
            geomean(&ratios[1]),
            faster(&ratios[1]),
            ratios[1].len()
        );
    }
}

/// What a query costs besides its walk (benches/shared/floor.rs): ns per ray on a scene of one
/// triangle, rayq's two structures and, with the peers, Embree MEDIUM (`rtcIntersect1`), thread
/// CPU time, medians of 5.
fn floor_section(md: &mut String) {
    let _ = writeln!(
        md,
        "## A query's fixed cost\n\nns per ray on a scene of one triangle (every structure one leaf \
         or cell; benches/shared/floor.rs), one thread, medians of 5: what a query pays besides its \
         walk — preparing the ray, and for a hit the exact test.\n\n| rays | rayq kd-tree | rayq grid \
         | Embree MEDIUM |\n|---|---:|---:|---:|"
    );
    for c in floor::measure(5) {
        let embree = c.embree.map_or_else(|| "—".into(), |e| format!("{e:.1}"));
        let _ = writeln!(
            md,
            "| {} | {:.1} | {:.1} | {embree} |",
            c.what, c.kd, c.grid
        );
    }
    md.push('\n');
}

/// The strategies' totals, AUTO's with trial builds at `share` of the grid's estimated time (0: none).
fn totals(o: &Observation, known: &Selector, unknown: &Selector, r: f64, share: f64) -> Totals {
    totals_capped(o, known, unknown, r, share, None, false)
}

/// [`totals`], with a known budget's trial build (below the estimated W*) abandoned once it has
/// taken `cap` times the grid's estimated trace time of the budget, when `cap` is given (or
/// earlier, where the work limit already stops it). The unknown budget's switch is not capped.
/// `keep_grid`: a known budget's grid kept while the kd-tree is built (as the online switch keeps
/// it), so that a tree abandoned or dropped by the check costs no second grid build.
fn totals_capped(
    o: &Observation,
    known: &Selector,
    unknown: &Selector,
    r: f64,
    share: f64,
    cap: Option<f64>,
    keep_grid: bool,
) -> Totals {
    let (g, b) = (o.grid_build_ns * 1e-9, o.kd_build_ns * 1e-9);
    let (tg, tk) = (o.grid_ray_ns * 1e-9, o.kd_ray_ns * 1e-9);
    let grid = g + r * tg;
    let kd = b + r * tk;
    let trial = r < known.estimate.break_even_rays();
    let capped = match cap.map(|c| c * r * known.estimate.grid_ray_seconds) {
        Some(limit) if trial && b > limit => Selector {
            abandoned_s: Some(known.abandoned_s.map_or(limit, |a| a.min(limit))),
            ..*known
        },
        _ => *known,
    };
    let auto_known = g
        + known.sample_s
        + if r >= known.estimate.build_rays_at(share) {
            after_switch(o, &capped, 0.0, r, !keep_grid)
        } else {
            r * tg
        };
    let switch = unknown.estimate.build_rays_at(share).ceil();
    let auto_unknown = g
        + unknown.sample_s
        + if r > switch {
            after_switch(o, unknown, switch, r, false)
        } else {
            r * tg
        };
    Totals {
        grid,
        kd,
        auto_known,
        auto_unknown,
        oracle: grid.min(kd),
    }
}

fn fmt_w(w: f64) -> String {
    if w.is_finite() {
        format!("{w:.3e}")
    } else {
        "∞".into()
    }
}

fn geomean(v: &[f64]) -> f64 {
    (v.iter().map(|x| x.ln()).sum::<f64>() / v.len().max(1) as f64).exp()
}

fn main() {
    let args = parse();
    let mut params = MeasureParams::DEFAULT;
    if args.quick {
        params.workload_side = 64;
        params.repeats = 2;
    }
    let specs = scene_set(args.quick);
    println!(
        "evaluating {} scenes{}",
        specs.len(),
        if args.quick { " (quick)" } else { "" }
    );
    let mut results: Vec<Measured> = Vec::new();
    for (i, spec) in specs.iter().enumerate() {
        let t = std::time::Instant::now();
        match measure_scene(spec, &params, args.quick) {
            Some(m) => {
                println!(
                    "[{:>2}/{}] {:<18} N={:>8}  grid {:>8.2} ms {:>6.0} ns/ray | kd {:>8.1} ms {:>6.0} ns/ray | W* {}  ({:.1} s)",
                    i + 1,
                    specs.len(),
                    m.name,
                    m.triangles,
                    m.obs.grid_build_ns * 1e-6,
                    m.obs.grid_ray_ns,
                    m.obs.kd_build_ns * 1e-6,
                    m.obs.kd_ray_ns,
                    fmt_w(m.obs.measured_break_even()),
                    t.elapsed().as_secs_f64()
                );
                results.push(m);
            }
            None => eprintln!(
                "[{:>2}/{}] {}: could not be measured",
                i + 1,
                specs.len(),
                spec.name
            ),
        }
    }
    if results.len() < 3 {
        eprintln!("too few scenes");
        std::process::exit(1);
    }
    std::fs::create_dir_all(&args.out).ok();
    let mut report = analyse(&results, &args);
    println!("timing the interior camera case");
    match interior::section(if args.quick { 1 } else { 5 }) {
        Some(md) => report.push_str(&md),
        None => eprintln!("../shared/scenes/sibenik.obj not found: no interior camera section"),
    }
    let path = args.out.join("evaluation.md");
    std::fs::write(&path, report).expect("write docs/evaluation.md");
    println!("wrote {}", path.display());
}

fn write_chart(args: &Args, file: &str, chart: &Chart) {
    let p = args.out.join(file);
    if let Err(e) = std::fs::write(&p, chart.svg()) {
        eprintln!("cannot write {}: {e}", p.display());
    }
}

/// The observations with the sample features of `SAMPLE_SIDES[k]` (what the selector would see with
/// that many sample rays).
fn with_side(results: &[Measured], k: usize) -> Vec<Observation> {
    results
        .iter()
        .map(|m| Observation {
            sample: m.samples[k].0,
            ..m.obs
        })
        .collect()
}

/// The check after a kd-tree build (`kd_tree_confirmed`) against the measured per-ray times: how
/// often it keeps the faster structure with the library's prices, and with prices fitted on this
/// run's measurements (`select::fit::fit_check_prices`; in-sample, and leave-one-out so that the
/// fit's optimism shows).
fn check_section(md: &mut String, results: &[Measured]) {
    // The library's default sample rays.
    let default_side = SampleParams::DEFAULT.camera_side;
    let k = SAMPLE_SIDES
        .iter()
        .position(|&s| s == default_side)
        .unwrap_or(SAMPLE_SIDES.len() - 1);
    let calibration = rayq::Calibration::builtin();
    // What a verdict costs on scene `m`: the kept structure's time per ray over the faster one's,
    // less one (0 when it keeps the faster).
    let kept_loss = |m: &Measured, keeps_kd: bool| {
        let (g, kd) = (m.obs.grid_ray_ns, m.obs.kd_ray_ns);
        let kept = if keeps_kd { kd } else { g };
        kept / g.min(kd) - 1.0
    };
    let loss = |m: &Measured, prices: &CheckPrices| {
        let keeps_kd =
            kd_tree_confirmed_at(calibration, &m.samples[k].0, &m.kd_samples[k].0, prices);
        kept_loss(m, keeps_kd)
    };
    // A row of the table: how often `keeps_kd` keeps the faster, the summed loss, the worst.
    let row = |md: &mut String, label: &str, keeps_kd: &dyn Fn(&Measured) -> bool| {
        let losses: Vec<(f64, &str)> = results
            .iter()
            .map(|m| (kept_loss(m, keeps_kd(m)), m.name.as_str()))
            .collect();
        let worst = losses
            .iter()
            .copied()
            .fold((0.0, ""), |a, b| if b.0 > a.0 { b } else { a });
        let _ = writeln!(
            md,
            "| {label} | {} of {} | {:.3} | {} {:.1} % |",
            losses.iter().filter(|l| l.0 == 0.0).count(),
            results.len(),
            losses.iter().map(|l| l.0).sum::<f64>(),
            worst.1,
            100.0 * worst.0
        );
    };
    let observation = |m: &Measured| CheckObservation {
        grid: m.samples[k].0,
        kd: m.kd_samples[k].0,
        grid_ray_ns: m.obs.grid_ray_ns,
        kd_ray_ns: m.obs.kd_ray_ns,
    };
    let fitted = |skip: Option<usize>| {
        let obs: Vec<CheckObservation> = results
            .iter()
            .enumerate()
            .filter(|&(i, _)| Some(i) != skip)
            .map(|(_, m)| observation(m))
            .collect();
        fit_check_prices(&obs, calibration)
    };
    let _ = writeln!(
        md,
        "\n### The check after a kd-tree build\n\nThe kd-tree is kept only if its time per ray on \
         the sample rays, priced from their counted work, is below the grid's (`kd_tree_confirmed`): \
         the grid's by the calibration's grid model, the kd-tree's at a share of the grid's fixed \
         cost per ray, a share of a cell step per node and a multiple of a grid test per test. \
         Against the measured per-ray times of the workload, on the {} scenes (the library's default \
         sample rays); *loss*: the kept structure's time per ray over the faster one's, summed over \
         the scenes; *fitted*: least squares of the measured kd-tree − grid time per ray \
         (`fit_check_prices`):\n",
        results.len()
    );
    let _ = writeln!(
        md,
        "| prices (fixed, node, test) | keeps the faster | loss | worst |\n|---|---:|---:|---|"
    );
    // The prices least squares gave at stop 27 (`CheckPrices::LIBRARY` says why the library does
    // not use them), judged on this run's measurements, which did not fit them.
    let stop27 = CheckPrices {
        fixed_per_grid_fixed: 0.62,
        node_per_cell_step: 0.53,
        test_per_grid_test: 1.47,
    };
    let mut rows = vec![
        ("the library's", Some(CheckPrices::LIBRARY)),
        ("fitted at stop 27", Some(stop27)),
    ];
    rows.push(("fitted on this run", fitted(None)));
    for (label, prices) in rows {
        let Some(p) = prices else {
            let _ = writeln!(md, "| {label}: no fit | | | |");
            continue;
        };
        let label = format!(
            "{label}: {:.2}, {:.2}, {:.2}",
            p.fixed_per_grid_fixed, p.node_per_cell_step, p.test_per_grid_test
        );
        row(md, &label, &|m| {
            kd_tree_confirmed_at(calibration, &m.samples[k].0, &m.kd_samples[k].0, &p)
        });
    }
    let loo: Vec<f64> = (0..results.len())
        .filter_map(|i| fitted(Some(i)).map(|p| loss(&results[i], &p)))
        .collect();
    let _ = writeln!(
        md,
        "| leave-one-out (each scene judged by prices fitted on the others) | {} of {} | {:.3} | |",
        loo.iter().filter(|&&l| l == 0.0).count(),
        loo.len(),
        loo.iter().sum::<f64>()
    );
    // The timed check (the library's for the caller's rays): both structures' time on the samples.
    row(
        md,
        "timed by the clock (what the library does for the caller's rays, not its own)",
        &|m| {
            let (grid_ns, kd_ns) = m.timed_samples[k];
            kd_tree_confirmed_timed(&m.samples[k].0, grid_ns as u64, kd_ns as u64)
        },
    );
    // A renderer that passes its own bounces as samples (the README's advice for bounce-heavy
    // work): every 16th of the workload's bounces, judged against the bounces' measured times.
    let judged: Vec<(&BounceCheck, f64)> = results
        .iter()
        .filter_map(|m| {
            let b = m.bounce_check.as_ref()?;
            let (kd, grid) = m.by_kind[1]?;
            Some((b, kd / grid))
        })
        .collect();
    let mut right = [0usize; 2];
    let mut lost = [0.0f64; 2];
    for (b, ratio) in &judged {
        let verdicts = [
            kd_tree_confirmed(calibration, &b.grid, &b.kd),
            kd_tree_confirmed_timed(&b.grid, b.grid_ns as u64, b.kd_ns as u64),
        ];
        for (j, keeps_kd) in verdicts.into_iter().enumerate() {
            right[j] += usize::from(keeps_kd == (*ratio < 1.0));
            lost[j] += if keeps_kd {
                ratio.max(1.0)
            } else {
                (1.0 / ratio).max(1.0)
            } - 1.0;
        }
    }
    let _ = writeln!(
        md,
        "\nThe same check when the samples are the renderer's diffuse bounces (every 16th of the \
         workload's, passed as the caller's sample rays; median {} rays), against the bounces' \
         measured times (section \"Camera rays and bounces apart\"):\n\n\
         | check | keeps the faster | loss |\n|---|---:|---:|\n\
         | priced (the library's prices; the library without a clock) | {} of {} | {:.3} |\n\
         | timed (the library with a clock) | {} of {} | {:.3} |",
        {
            let mut n: Vec<f64> = judged.iter().map(|j| j.0.grid.rays as f64).collect();
            median(&mut n)
        },
        right[0],
        judged.len(),
        lost[0],
        right[1],
        judged.len(),
        lost[1]
    );
    // AUTO for such a renderer on a workload of bounces: its estimate from the bounce samples (the
    // built-in calibration), its check priced or timed, totals against the bounces' measured times.
    let mut regret: [Regrets; 2] = Default::default();
    for m in results {
        let Some((b, o)) = on_bounces(m) else {
            continue;
        };
        for (j, (confirmed, check_ns)) in [
            (
                kd_tree_confirmed(calibration, &b.grid, &b.kd),
                b.kd_counted_ns,
            ),
            (
                kd_tree_confirmed_timed(&b.grid, b.grid_ns as u64, b.kd_ns as u64),
                b.grid_ns + b.kd_ns,
            ),
        ]
        .into_iter()
        .enumerate()
        {
            let sel = Selector {
                estimate: calibration.estimate(&b.grid),
                sample_s: b.grid_counted_ns * 1e-9,
                confirmed,
                check_s: check_ns * 1e-9,
                abandoned_s: m.abandoned_s,
            };
            for r in budgets() {
                let t = totals(&o, &sel, &sel, r, TRIAL_SHARE);
                regret[j].add(t.auto_known / t.oracle, &m.name, r);
            }
        }
    }
    let _ = writeln!(
        md,
        "\nAUTO for that renderer on a workload of bounces (known budgets 10³..10⁸, the estimate \
         from the bounce samples with the built-in calibration, totals against the bounces' measured \
         times): regret {} with the check priced, {} timed.",
        regret[0].summary(),
        regret[1].summary()
    );
}

/// Issue 14's goal for the worst regret (AUTO / oracle) over the scenes and known budgets.
const WORST_REGRET_GOAL: f64 = 1.25;

fn analyse(results: &[Measured], args: &Args) -> String {
    let obs: Vec<Observation> = results.iter().map(|m| m.obs).collect();
    // The variant the built-in calibration was fitted with (the variants table below compares
    // them all on these measurements).
    let (variant, terms) = VARIANTS
        .iter()
        .copied()
        .find(|(label, _)| *label == BUILTIN_VARIANT)
        .unwrap_or_else(|| {
            let (label, terms, _) = best_variant(&obs);
            (label, terms)
        });
    let loo = cross_validated_break_even(&obs, &terms, 0, GridCost::Counted);
    let kfold = cross_validated_break_even(&obs, &terms, 4, GridCost::Counted);
    let clock = cross_validated_errors(&obs, &terms, 0, GridCost::Clock);
    let measured: Vec<f64> = obs.iter().map(|o| o.measured_break_even()).collect();
    let mut loo_err: Vec<f64> = loo
        .iter()
        .zip(&measured)
        .map(|(e, m)| relative_error(*e, *m))
        .collect();
    let mut kfold_err: Vec<f64> = kfold
        .iter()
        .zip(&measured)
        .map(|(e, m)| relative_error(*e, *m))
        .collect();
    // The selector's estimate and sampling time depend on the budget: the library caps its sample
    // rays (SampleParams::for_budget: by the budget when it is known, at UNKNOWN_BUDGET_SIDE when it
    // is not); take the measured side at or below the one it would use. Its calibration is fitted
    // on the default side's samples (as `calibrate` fits it) and applied to that side's features.
    let loo_by_side: Vec<Vec<CostEstimate>> = (0..SAMPLE_SIDES.len())
        .map(|k| {
            cross_validated_estimates_for(
                &obs,
                &with_side(results, k),
                &terms,
                0,
                GridCost::Counted,
            )
        })
        .collect();
    let side_index = |r: f64| {
        let side = SampleParams::DEFAULT.for_budget(r as u64).camera_side;
        SAMPLE_SIDES.iter().rposition(|&s| s <= side).unwrap_or(0)
    };
    // What the selector sees on scene `i` with the samples of side `SAMPLE_SIDES[k]` and the
    // estimates `loo` (per sample side, per scene: the library's variant, or another for the
    // variants table); `selector_with` takes the side the library uses for budget `r` (0 =
    // unknown).
    // The check on the library's samples as a scene makes it: `priced` from the kd-tree's counted
    // work (even with a clock: `BuildOptions::clock`); or, for comparison, timed on both structures.
    let selector_by = |loo: &[Vec<CostEstimate>], k: usize, i: usize, priced: bool| {
        let m = &results[i];
        let (grid_ns, kd_ns) = m.timed_samples[k];
        let (confirmed, check_ns) = if priced {
            let keep = kd_tree_confirmed(
                rayq::Calibration::builtin(),
                &m.samples[k].0,
                &m.kd_samples[k].0,
            );
            (keep, m.kd_samples[k].1)
        } else {
            let keep = kd_tree_confirmed_timed(&m.samples[k].0, grid_ns as u64, kd_ns as u64);
            (keep, grid_ns + kd_ns)
        };
        Selector {
            estimate: loo[k][i],
            sample_s: m.samples[k].1 * 1e-9,
            confirmed,
            check_s: check_ns * 1e-9,
            abandoned_s: m.abandoned_s,
        }
    };
    let selector_at = |loo: &[Vec<CostEstimate>], k: usize, i: usize| selector_by(loo, k, i, true);
    let selector_with =
        |loo: &[Vec<CostEstimate>], i: usize, r: f64| selector_at(loo, side_index(r), i);
    let selector = |i: usize, r: f64| selector_with(&loo_by_side, i, r);
    // Regret (AUTO / oracle) over the scenes and known budgets with the estimates `loo` and the
    // check timed or `priced`: the geometric mean, the worst and where.
    let regret_by = |loo: &[Vec<CostEstimate>], priced: bool| {
        let (mut q, mut worst) = (Vec::new(), (1.0f64, String::new()));
        for (i, m) in results.iter().enumerate() {
            for r in budgets() {
                let t = totals(
                    &m.obs,
                    &selector_by(loo, side_index(r), i, priced),
                    &selector_by(loo, side_index(0.0), i, priced),
                    r,
                    TRIAL_SHARE,
                );
                let x = t.auto_known / t.oracle;
                q.push(x);
                if x > worst.0 {
                    worst = (x, format!("{} at {r:.0e}", m.name));
                }
            }
        }
        (geomean(&q), worst)
    };
    let regret_with = |loo: &[Vec<CostEstimate>]| regret_by(loo, true);
    let at_share = |i: usize, r: f64, share: f64| {
        totals(
            &results[i].obs,
            &selector(i, r),
            &selector(i, 0.0),
            r,
            share,
        )
    };
    let at = |i: usize, r: f64| at_share(i, r, TRIAL_SHARE);

    let mut md = String::new();
    let _ = writeln!(md, "# Evaluation\n");
    let _ = writeln!(
        md,
        "Generated by `cargo run --release --example evaluate{}{}` on the project's 2-core VM \
         (timings are thread CPU time, medians of {} repeats; the spread column gives the slowest / \
         fastest repeat of the kd-tree build). Workload per scene: {}² camera rays plus one diffuse \
         bounce per hit. Do not edit by hand: rerun the command.\n",
        if args.quick { " -- --quick" } else { "" },
        if cfg!(feature = "peers") { " --features peers" } else { "" },
        if args.quick { 2 } else { 3 },
        if args.quick { 64 } else { 128 }
    );
    let _ = writeln!(md, "## Summary\n");
    let mut regrets = Vec::new();
    let mut worst = (1.0f64, String::new());
    let mut worst_unknown = (1.0f64, String::new());
    let mut right = 0usize;
    let mut decisions = 0usize;
    // The cases above the worst-case goal, for the line under the summary.
    let mut above_goal = Vec::new();
    // Why: the estimates against the measurements on each of them.
    let mut why_above = String::new();
    for (i, m) in results.iter().enumerate() {
        for r in budgets() {
            let t = at(i, r);
            let q = t.auto_known / t.oracle;
            regrets.push(q);
            if q > WORST_REGRET_GOAL {
                above_goal.push(format!("{} at {r:.0e} ({q:.2})", m.name));
                let (sel, o) = (selector(i, r), &m.obs);
                let (e, trial_rays) = (sel.estimate, sel.estimate.trial_rays());
                let _ = writeln!(
                    why_above,
                    "| {} | {r:.0e} | {q:.2} | {:.0} / {:.0} | {:.0} / {:.0} | {:.1} / {:.1} | {} | {} |",
                    m.name,
                    e.grid_ray_seconds * 1e9,
                    o.grid_ray_ns,
                    e.kd_ray_seconds * 1e9,
                    o.kd_ray_ns,
                    e.kd_build_seconds * 1e3,
                    o.kd_build_ns * 1e-6,
                    fmt_w(trial_rays),
                    // NaN estimates never build (as `totals` prices them).
                    if sel.estimate.build_rays() <= r {
                        if sel.abandoned_s.is_some() {
                            "abandoned"
                        } else if !sel.confirmed {
                            "dropped"
                        } else {
                            "kd-tree"
                        }
                    } else {
                        "grid"
                    },
                );
            }
            decisions += 1;
            let sel = selector(i, r);
            right += usize::from(
                (r >= sel.estimate.build_rays() && sel.confirmed && sel.abandoned_s.is_none())
                    == (t.kd < t.grid),
            );
            if q > worst.0 {
                worst = (q, format!("{} at R = {r:.0e}", m.name));
            }
            let u = t.auto_unknown / t.oracle;
            if u > worst_unknown.0 {
                worst_unknown = (u, format!("{} at R = {r:.0e}", m.name));
            }
        }
    }
    let _ = writeln!(md, "| measure | value | goal |\n|---|---:|---:|");
    // Per scene, in the scenes' order (`median` sorts what it is given).
    let loo_by_scene = loo_err.clone();
    let _ = writeln!(
        md,
        "| median \\|W*est / W*meas − 1\\|, leave-one-out | {:.1} % | ≤ 20 % (issue 14; project 10 %) |",
        100.0 * median(&mut loo_err)
    );
    // Issue 14 asks for the hair, stadium and interior-camera cases apart (the interior case's
    // error is in its own section): each scene's, as the groups are small. A finite estimate
    // against an infinite measurement (or the reverse) counts 100 %.
    let errors_of = |pick: &dyn Fn(&Measured) -> bool| {
        let each: Vec<String> = results
            .iter()
            .zip(&loo_by_scene)
            .filter(|(m, _)| pick(m))
            .map(|(m, e)| format!("{} {:.0} %", m.name, 100.0 * e))
            .collect();
        if each.is_empty() {
            "—".to_string()
        } else {
            each.join(", ")
        }
    };
    let _ = writeln!(
        md,
        "| the same per scene, hair / stadiums (the interior camera: its section) | {} / {} | |",
        errors_of(&|m: &Measured| m.name.starts_with("hair")),
        errors_of(&|m: &Measured| m.name.contains("stadium"))
    );
    let _ = writeln!(
        md,
        "| the same, 4-fold | {:.1} % | |",
        100.0 * median(&mut kfold_err)
    );
    let _ = writeln!(
        md,
        "| the same with the grid's sample rays timed by the clock | {:.1} % | |",
        100.0 * median(&mut clock.clone())
    );
    // What W* is made of, judged apart: the estimate's kd-tree / grid time per ray and its build
    // (leave-one-out, the default sample rays), and how many scenes leave W* room to be within 20 %
    // at all. With the ratio r = t_kd / t_grid known within a relative δ, W* = T / (t_grid·(1 − r))
    // moves by about r·δ / (1 − r), at most 20 % only while r ≤ 0.2 / (δ + 0.2).
    let default_side = side_index(0.0);
    let mut ratio_err: Vec<f64> = results
        .iter()
        .zip(&loo_by_side[default_side])
        .map(|(m, e)| {
            let est = e.kd_ray_seconds / e.grid_ray_seconds;
            (est / (m.obs.kd_ray_ns / m.obs.grid_ray_ns)).ln().abs()
        })
        .collect();
    let mut build_err: Vec<f64> = results
        .iter()
        .zip(&loo_by_side[default_side])
        .map(|(m, e)| (e.kd_build_seconds / (m.obs.kd_build_ns * 1e-9)).ln().abs())
        .collect();
    let delta = median(&mut ratio_err).exp() - 1.0;
    let reachable = results
        .iter()
        .filter(|m| m.obs.kd_ray_ns / m.obs.grid_ray_ns <= 0.2 / (delta + 0.2))
        .count();
    let _ = writeln!(
        md,
        "| its parts: kd-tree / grid time per ray, median \\|ln(est / meas)\\|, leave-one-out | {:.3} | |",
        median(&mut ratio_err)
    );
    let _ = writeln!(
        md,
        "| its parts: kd-tree build, median \\|ln(est / meas)\\|, leave-one-out | {:.3} | |",
        median(&mut build_err)
    );
    let _ = writeln!(
        md,
        "| scenes whose measured kd/grid per ray (≤ {:.2}) leaves W* within 20 % reachable at that ratio error | {reachable} of {} | |",
        0.2 / (delta + 0.2),
        results.len()
    );
    let _ = writeln!(md, "| regret (AUTO / oracle), geometric mean over scenes × budgets 10³..10⁸ | {:.3} | ≤ 1.03 |", geomean(&regrets));
    let _ = writeln!(
        md,
        "| regret, worst ({}) | {:.3} | ≤ {WORST_REGRET_GOAL} |",
        worst.1, worst.0
    );
    let _ = writeln!(
        md,
        "| unknown budget (online switch), worst ({}) | {:.3} | ≤ 1.8 |",
        worst_unknown.1, worst_unknown.0
    );
    let (timed_mean, timed_worst) = regret_by(&loo_by_side, false);
    let _ = writeln!(
        md,
        "| the same regret were the check on the library's samples timed (it is priced): geometric mean, worst ({}) | {:.3}, {:.3} | |",
        timed_worst.1, timed_mean, timed_worst.0
    );
    let _ = writeln!(
        md,
        "| decisions that match the oracle | {right} of {decisions} | |"
    );
    let _ = writeln!(
        md,
        "| model variant (the built-in calibration's) | {variant} | |\n"
    );
    let _ = writeln!(
        md,
        "Known budgets whose regret is above {WORST_REGRET_GOAL}: {}.\n",
        if above_goal.is_empty() {
            "none".to_string()
        } else {
            above_goal.join(", ")
        }
    );
    if !why_above.is_empty() {
        let _ = writeln!(
            md,
            "Their estimates (leave-one-out) against the measurements: time per ray in ns, the \
             kd-tree's build in ms, the budget from which a trial is built, and what AUTO did.\n\n\
             | scene | R | regret | grid/ray est / meas | kd/ray est / meas | kd build est / meas | \
             trial from | AUTO |\n|---|---:|---:|---:|---:|---:|---:|---|\n{why_above}"
        );
    }

    // Per-scene table.
    let _ = writeln!(md, "## Per scene\n");
    let _ = writeln!(
        md,
        "Times: builds in ms, per ray in ns (medians; kd build spread = slowest/fastest). W* est is \
         leave-one-out. Lost: AUTO's total time over the oracle's at R = 10⁴ / 10⁶ / 10⁸ rays.\n"
    );
    let _ = writeln!(md, "| scene | group | N | grid build | kd build (spread) | grid/ray | kd/ray | W* meas | W* est | ratio | lost 10⁴ / 10⁶ / 10⁸ |");
    let _ = writeln!(md, "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for (i, (m, &w_est)) in results.iter().zip(&loo).enumerate() {
        let o = &m.obs;
        let w = o.measured_break_even();
        let lost: Vec<String> = [1e4, 1e6, 1e8]
            .iter()
            .map(|&r| {
                let t = at(i, r);
                format!("{:+.0} %", 100.0 * (t.auto_known / t.oracle - 1.0))
            })
            .collect();
        let ratio = if w.is_finite() && w_est.is_finite() && w > 0.0 {
            format!("{:.2}", w_est / w)
        } else if w.is_infinite() && w_est.is_infinite() {
            "∞/∞".into()
        } else {
            "—".into()
        };
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.2} | {:.1} ({:.2}) | {:.0} | {:.0} | {} | {} | {} | {} |",
            m.name,
            m.group,
            m.triangles,
            o.grid_build_ns * 1e-6,
            o.kd_build_ns * 1e-6,
            m.spread.kd_build.max / m.spread.kd_build.min.max(1.0),
            o.grid_ray_ns,
            o.kd_ray_ns,
            fmt_w(w),
            fmt_w(w_est),
            ratio,
            lost.join(" / ")
        );
    }

    // The trial share against regret, on the same measurements.
    let _ = writeln!(
        md,
        "\n### Trial builds\n\nAUTO builds the kd-tree at the estimated W*, or as a trial once its \
         estimated build is at most a share of the grid's estimated trace time (the check after the \
         build keeps the faster structure). Regret over the scenes × budgets above for each share \
         (the library uses {:.4}), with the budget where the worst is; *capped*: the same with a \
         trial's build abandoned once it has taken the share of the grid's estimated trace time \
         (or where the work limit stops it first; simulated: the library caps a build's work, not \
         its time, and not by the budget), the rest of the rays on the grid, rebuilt; *grid kept*: \
         the grid kept while the kd-tree is built, so that an abandoned or dropped tree costs no \
         second grid build (the library releases it first); the unknown budget's column is not \
         capped:\n",
        TRIAL_SHARE
    );
    let _ = writeln!(
        md,
        "| share | regret geometric mean | worst | unknown budget worst | trials built |\n|---:|---:|---:|---:|---:|"
    );
    for (capped, keep_grid) in [(false, false), (true, false), (false, true), (true, true)] {
        for share in [
            0.0,
            1.0 / 64.0,
            1.0 / 32.0,
            1.0 / 16.0,
            1.0 / 8.0,
            1.0 / 4.0,
        ] {
            let (mut q, mut worst, mut worst_u, mut trials) =
                (Vec::new(), (1.0f64, String::new()), 1.0f64, 0usize);
            for (i, m) in results.iter().enumerate() {
                for r in budgets() {
                    let t = totals_capped(
                        &m.obs,
                        &selector(i, r),
                        &selector(i, 0.0),
                        r,
                        share,
                        capped.then_some(share),
                        keep_grid,
                    );
                    let x = t.auto_known / t.oracle;
                    q.push(x);
                    if x > worst.0 {
                        worst = (x, format!("{} at {r:.0e}", m.name));
                    }
                    worst_u = worst_u.max(t.auto_unknown / t.oracle);
                    let e = selector(i, r).estimate;
                    trials += usize::from(r < e.break_even_rays() && r >= e.build_rays_at(share));
                }
            }
            let _ = writeln!(
                md,
                "| {share:.4}{}{} | {:.3} | {:.3} ({}) | {worst_u:.3} | {trials} |",
                if capped { ", capped" } else { "" },
                if keep_grid { ", grid kept" } else { "" },
                geomean(&q),
                worst.0,
                worst.1
            );
        }
    }

    check_section(&mut md, results);

    // A renderer that traces bounces and passes no samples: AUTO decides on its own samples (as
    // above), and a kd-tree it keeps is checked again on the tapped queries after the first batch
    // (`Scene::update`, with a clock): timed on the kd-tree, a grid built, timed on it, the faster
    // kept. Batches of 1 % of the budget or 20 000 rays (enough to tap 256), the verdict the timed
    // check's on the bounce samples, the cost the grid's build and three passes of 1 024 rays.
    let mut regret: [Regrets; 2] = Default::default();
    for (i, m) in results.iter().enumerate() {
        let Some((b, o)) = on_bounces(m) else {
            continue;
        };
        let (kd, grid) = (o.kd_ray_ns, o.grid_ray_ns);
        for r in budgets() {
            let sel = selector(i, r);
            let t = totals(&o, &sel, &selector(i, 0.0), r, TRIAL_SHARE);
            let on_kd =
                r >= sel.estimate.build_rays() && sel.confirmed && sel.abandoned_s.is_none();
            let batch = (r / 100.0).max(20_000.0);
            let rechecked = if on_kd && r > batch {
                let grid_wins = b.grid_ns < b.kd_ns;
                let after = if grid_wins { grid } else { kd };
                let cost = m.obs.grid_build_ns + 1024.0 * (kd + 2.0 * grid);
                t.auto_known + (cost + (r - batch) * (after - kd)) * 1e-9
            } else {
                t.auto_known
            };
            for (j, total) in [t.auto_known, rechecked].into_iter().enumerate() {
                regret[j].add(total / t.oracle, &m.name, r);
            }
        }
    }
    let _ = writeln!(
        md,
        "\nAUTO for a renderer that traces bounces and passes no samples (its own samples decide, \
         the leave-one-out estimates; known budgets 10³..10⁸; totals against the bounces' measured \
         times): regret {} were the kd-tree it keeps final; {} with the library's check of that \
         kd-tree on the tapped queries after the first batch (simulated: batches of 1 % of the \
         budget or 20 000 rays, the timed check's verdict on the bounce samples, a grid build and \
         three passes of 1 024 rays).",
        regret[0].summary(),
        regret[1].summary()
    );

    // Charts.
    let _ = writeln!(md, "\n## Charts\n");
    let groups = [
        "scanned",
        "CAD",
        "architecture & terrain",
        "stadium",
        "procedural",
    ];
    for g in groups {
        let Some((i, m)) = results
            .iter()
            .enumerate()
            .filter(|(_, m)| m.group == g)
            .max_by_key(|(_, m)| m.triangles)
        else {
            continue;
        };
        let b = budgets();
        let curve = |label: &str, mark: Mark, f: &dyn Fn(f64) -> f64| Series {
            label: label.to_string(),
            points: b.iter().map(|&r| (r, f(r))).collect(),
            mark,
        };
        let mut series = vec![
            curve("grid only", Mark::Line, &|r| at(i, r).grid),
            curve("kd-tree only", Mark::Line, &|r| at(i, r).kd),
            curve("AUTO, R known", Mark::Dashed, &|r| at(i, r).auto_known),
            curve("AUTO, R unknown", Mark::Dashed, &|r| at(i, r).auto_unknown),
        ];
        for p in &m.peers {
            series.push(curve(&p.label, Mark::Line, &|r| {
                (p.build_ns + r * p.ray_ns) * 1e-9
            }));
        }
        let file = format!(
            "evaluation_total_{}.svg",
            g.split(' ').next().unwrap_or(g).to_lowercase()
        );
        write_chart(
            args,
            &file,
            &Chart {
                title: format!(
                    "{} ({}, {} triangles): build + rays",
                    m.name, g, m.triangles
                ),
                x_label: "rays traced R".into(),
                y_label: "total seconds".into(),
                log_x: true,
                log_y: true,
                series,
            },
        );
        let _ = writeln!(md, "![total time, {g}]({file})\n");
    }
    let finite: Vec<(f64, f64)> = measured
        .iter()
        .zip(&loo)
        .filter(|(m, e)| m.is_finite() && e.is_finite() && **m > 0.0 && **e > 0.0)
        .map(|(m, e)| (*m, *e))
        .collect();
    let lo = finite
        .iter()
        .map(|p| p.0.min(p.1))
        .fold(f64::INFINITY, f64::min);
    let hi = finite.iter().map(|p| p.0.max(p.1)).fold(0.0, f64::max);
    write_chart(
        args,
        "evaluation_wstar.svg",
        &Chart {
            title: "W*: estimated (leave-one-out) vs measured".into(),
            x_label: "measured W* (rays)".into(),
            y_label: "estimated W* (rays)".into(),
            log_x: true,
            log_y: true,
            series: vec![
                Series {
                    label: "scenes".into(),
                    points: finite.clone(),
                    mark: Mark::Dots,
                },
                Series {
                    label: "exact".into(),
                    points: vec![(lo, lo), (hi, hi)],
                    mark: Mark::Dashed,
                },
            ],
        },
    );
    let _ = writeln!(
        md,
        "![estimated vs measured W*](evaluation_wstar.svg)\n\n{} of {} scenes have a finite measured and \
         estimated W*; the others are the kd-tree never paying (measured, estimated, or both).\n",
        finite.len(),
        results.len()
    );

    // Speed vs accuracy: sample rays vs W* error and overhead.
    let mut err_pts = Vec::new();
    let mut over_pts = Vec::new();
    let _ = writeln!(md, "### Sample rays: accuracy against overhead\n");
    let _ = writeln!(
        md,
        "The unknown budget's columns: AUTO with that many library samples and no budget (the \
         online switch; the library uses a side of {UNKNOWN_BUDGET_SIDE}), over the scenes × \
         budgets above: its regret's geometric mean and worst, the calibration fitted on the \
         default side's samples (leave-one-out) and applied to that side's.\n"
    );
    let _ = writeln!(md, "| camera side | sample rays (median) | leave-one-out W* error | overhead at R = W* (median) | unknown budget: regret geometric mean | worst |\n|---:|---:|---:|---:|---:|---|");
    for (k, side) in SAMPLE_SIDES.iter().enumerate() {
        let mut e = cross_validated_errors(&with_side(results, k), &terms, 0, GridCost::Counted);
        let mut rays: Vec<f64> = results.iter().map(|m| m.samples[k].0.rays as f64).collect();
        let mut over: Vec<f64> = results
            .iter()
            .filter_map(|m| {
                let w = m.obs.measured_break_even();
                w.is_finite()
                    .then(|| m.samples[k].1 / (m.obs.grid_build_ns + w * m.obs.grid_ray_ns))
            })
            .collect();
        let (me, mr, mo) = (median(&mut e), median(&mut rays), median(&mut over));
        err_pts.push((mr, 100.0 * me));
        over_pts.push((mr, 100.0 * mo));
        // The online switch with this side's samples (the known budget's selector is not used).
        let (mut q, mut worst) = (Vec::new(), (1.0f64, String::new()));
        for (i, m) in results.iter().enumerate() {
            let unknown = selector_at(&loo_by_side, k, i);
            for r in budgets() {
                let t = totals(&m.obs, &unknown, &unknown, r, TRIAL_SHARE);
                let x = t.auto_unknown / t.oracle;
                q.push(x);
                if x > worst.0 {
                    worst = (x, format!("{} at {r:.0e}", m.name));
                }
            }
        }
        let _ = writeln!(
            md,
            "| {side} | {mr:.0} | {:.1} % | {:.3} % | {:.3} | {:.3} ({}) |",
            100.0 * me,
            100.0 * mo,
            geomean(&q),
            worst.0,
            worst.1
        );
    }
    write_chart(
        args,
        "evaluation_samples.svg",
        &Chart {
            title: "Sample rays: W* error and selection overhead".into(),
            x_label: "sample rays per scene (median)".into(),
            y_label: "percent".into(),
            log_x: true,
            log_y: true,
            series: vec![
                Series {
                    label: "W* error (LOO)".into(),
                    points: err_pts,
                    mark: Mark::Line,
                },
                Series {
                    label: "overhead at R = W*".into(),
                    points: over_pts,
                    mark: Mark::Line,
                },
            ],
        },
    );
    let _ = writeln!(
        md,
        "\n![sample rays against error and overhead](evaluation_samples.svg)\n"
    );

    // Model terms vs cross-validated error.
    let _ = writeln!(
        md,
        "### Model terms\n\nEach variant's leave-one-out estimates, and AUTO's regret over the scenes × known \
         budgets above with them (the library's trial share and check):\n\n| variant | terms | \
         leave-one-out W* error | regret geometric mean | worst |\n|---|---:|---:|---:|---|"
    );
    let mut term_pts = Vec::new();
    for (label, t) in VARIANTS {
        let n_terms: usize = Part::ALL
            .iter()
            .zip(t.0)
            .map(|(p, mask)| {
                mask.iter()
                    .take(p.constants().len())
                    .filter(|&&b| b)
                    .count()
            })
            .sum();
        let mut e = cross_validated_errors(&obs, &t, 0, GridCost::Counted);
        let me = median(&mut e);
        term_pts.push((n_terms as f64, 100.0 * me));
        let loo_t: Vec<Vec<CostEstimate>> = (0..SAMPLE_SIDES.len())
            .map(|k| {
                cross_validated_estimates_for(
                    &obs,
                    &with_side(results, k),
                    &t,
                    0,
                    GridCost::Counted,
                )
            })
            .collect();
        let (mean, (worst, at)) = regret_with(&loo_t);
        let _ = writeln!(
            md,
            "| {label} | {n_terms} | {:.1} % | {mean:.3} | {worst:.3} ({at}) |",
            100.0 * me
        );
    }
    write_chart(
        args,
        "evaluation_terms.svg",
        &Chart {
            title: "Model terms vs cross-validated W* error".into(),
            x_label: "terms in the model".into(),
            y_label: "median W* error (%)".into(),
            log_x: false,
            log_y: false,
            series: vec![Series {
                label: "variants".into(),
                points: term_pts,
                mark: Mark::Dots,
            }],
        },
    );
    let _ = writeln!(md, "\n![model terms against error](evaluation_terms.svg)\n");

    // Rays/s vs hit accuracy.
    struct Row {
        label: String,
        speed: Vec<f64>,
        wrong: Vec<f64>,
        wrong_workload: Vec<f64>,
        leaks: Vec<f64>,
    }
    let row = |label: &str| Row {
        label: label.into(),
        speed: vec![],
        wrong: vec![],
        wrong_workload: vec![],
        leaks: vec![],
    };
    let mut acc: Vec<Row> = vec![row("rayq grid"), row("rayq kd-tree")];
    let mut closed_scenes = 0;
    for m in results {
        if let Some([g, k]) = m.rayq_accuracy {
            closed_scenes += usize::from(g.leaks.is_some());
            for (i, (a, ns)) in [(g, m.obs.grid_ray_ns), (k, m.obs.kd_ray_ns)]
                .into_iter()
                .enumerate()
            {
                acc[i].speed.push(1e3 / ns);
                acc[i].wrong.push(a.wrong);
                acc[i].wrong_workload.push(a.wrong_workload);
                acc[i].leaks.extend(a.leaks);
            }
        }
        for p in &m.peers {
            if let Some(a) = p.accuracy {
                let i = match acc.iter().position(|r| r.label == p.label) {
                    Some(i) => i,
                    None => {
                        acc.push(row(&p.label));
                        acc.len() - 1
                    }
                };
                acc[i].speed.push(1e3 / p.ray_ns);
                acc[i].wrong.push(a.wrong);
                acc[i].wrong_workload.push(a.wrong_workload);
                acc[i].leaks.extend(a.leaks);
            }
        }
    }
    let _ = writeln!(
        md,
        "### Speed against hit accuracy\n\nAgainst the exact answers (rayq's brute force, whose test is \
         checked against an exact integer definition), on scenes up to 130k triangles, for a sample of \
         the workload's camera and bounce rays plus rays aimed from outside at vertices and edge \
         midpoints (examples/evaluate/accuracy.rs). *Wrong*: a miss where the exact answer hits, a hit \
         where it misses, or a triangle the exact test does not hit at the nearest t (ties at the same t \
         are right); given over all check rays and over the workload's rays alone. *Leaks* ({closed_scenes} \
         closed meshes): aimed rays whose exact hit is at or before the target but which the structure \
         reports as a miss or a hit beyond it. Rays/s over all scenes measured (median).\n\n\
         | structure | Mrays/s (median) | wrong answers (mean) | of them on workload rays | leaks on closed meshes (mean) |\n|---|---:|---:|---:|---:|"
    );
    let mut speed_series = Vec::new();
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    for r in &mut acc {
        if r.speed.is_empty() {
            continue;
        }
        let (mean_wrong, ms) = (mean(&r.wrong), median(&mut r.speed));
        let leaks = if r.leaks.is_empty() {
            "–".to_string()
        } else {
            format!("{:.3} %", 100.0 * mean(&r.leaks))
        };
        let _ = writeln!(
            md,
            "| {} | {ms:.2} | {:.4} % | {:.4} % | {leaks} |",
            r.label,
            100.0 * mean_wrong,
            100.0 * mean(&r.wrong_workload)
        );
        speed_series.push(Series {
            label: r.label.clone(),
            points: vec![(100.0 * mean_wrong.max(1e-4), ms)],
            mark: Mark::Dots,
        });
    }
    write_chart(
        args,
        "evaluation_accuracy.svg",
        &Chart {
            title: "Rays/s against wrong answers (exact reference)".into(),
            x_label: "wrong answers (%, mean over scenes; 1e-4 = none seen)".into(),
            y_label: "Mrays/s (median over scenes)".into(),
            log_x: true,
            log_y: true,
            series: speed_series,
        },
    );
    let _ = writeln!(md, "\n![speed against accuracy](evaluation_accuracy.svg)\n");

    // Peers: build and per-ray times side by side, and the kd-tree's ratios to Embree MEDIUM.
    if results.iter().any(|m| !m.peers.is_empty()) {
        let labels: Vec<String> = results
            .iter()
            .flat_map(|m| m.peers.iter().map(|p| p.label.clone()))
            .fold(Vec::new(), |mut v, l| {
                if !v.contains(&l) {
                    v.push(l);
                }
                v
            });
        let _ = writeln!(
            md,
            "## Peers, per scene\n\nBuild ms / ns per ray on the same workload rays (one thread). \
             kd/Embree: the kd-tree's throughput as a fraction of Embree MEDIUM's (`rtcIntersect1`), \
             and its build time as a multiple of Embree MEDIUM's.\n"
        );
        let _ = write!(md, "| scene | rayq grid | rayq kd-tree |");
        for l in &labels {
            let _ = write!(md, " {l} |");
        }
        let _ = writeln!(md, " kd/Embree rays | kd/Embree build |");
        let _ = writeln!(
            md,
            "|---|---:|---:|{}---:|---:|",
            "---:|".repeat(labels.len())
        );
        let mut ray_ratios = Vec::new();
        let mut build_ratios = Vec::new();
        for m in results {
            let o = &m.obs;
            let _ = write!(
                md,
                "| {} | {:.2} / {:.0} | {:.1} / {:.0} |",
                m.name,
                o.grid_build_ns * 1e-6,
                o.grid_ray_ns,
                o.kd_build_ns * 1e-6,
                o.kd_ray_ns
            );
            for l in &labels {
                match m.peers.iter().find(|p| &p.label == l) {
                    Some(p) => {
                        let _ = write!(md, " {:.2} / {:.0} |", p.build_ns * 1e-6, p.ray_ns);
                    }
                    None => md.push_str(" — |"),
                }
            }
            match m.peers.iter().find(|p| p.label == "Embree MEDIUM") {
                Some(p) => {
                    let (rr, br) = (p.ray_ns / o.kd_ray_ns, o.kd_build_ns / p.build_ns);
                    ray_ratios.push(rr);
                    build_ratios.push(br);
                    let _ = writeln!(md, " {rr:.2} | {br:.1}× |");
                }
                None => md.push_str(" — | — |\n"),
            }
        }
        if !ray_ratios.is_empty() {
            let _ = writeln!(
                md,
                "\nkd-tree throughput / Embree MEDIUM: geometric mean {:.3}, median {:.2} (range {:.2}–{:.2}); \
                 kd-tree build / Embree MEDIUM build: geometric mean {:.2}×, median {:.1}× (range {:.1}–{:.1}×).\n",
                geomean(&ray_ratios),
                median(&mut ray_ratios.clone()),
                ray_ratios.iter().copied().fold(f64::INFINITY, f64::min),
                ray_ratios.iter().copied().fold(0.0, f64::max),
                geomean(&build_ratios),
                median(&mut build_ratios.clone()),
                build_ratios.iter().copied().fold(f64::INFINITY, f64::min),
                build_ratios.iter().copied().fold(0.0, f64::max)
            );
        }
    }
    kinds_section(&mut md, results);
    floor_section(&mut md);

    // Peers: where AUTO has the lowest total.
    if results.iter().any(|m| !m.peers.is_empty()) {
        let _ = writeln!(md, "## AUTO against the peers\n\nAUTO's total time (known budget) over the best peer's build + trace, per budget.\n");
        let _ = writeln!(
            md,
            "| scene | 10³ | 10⁴ | 10⁵ | 10⁶ | 10⁷ | 10⁸ |\n|---|---:|---:|---:|---:|---:|---:|"
        );
        for (i, m) in results.iter().enumerate() {
            if m.peers.is_empty() {
                continue;
            }
            let cells: Vec<String> = (3..=8)
                .map(|e| {
                    let r = 10f64.powi(e);
                    let auto = at(i, r).auto_known;
                    let best = m
                        .peers
                        .iter()
                        .map(|p| (p.build_ns + r * p.ray_ns) * 1e-9)
                        .fold(f64::INFINITY, f64::min);
                    format!("{:.2}", auto / best)
                })
                .collect();
            let _ = writeln!(md, "| {} | {} |", m.name, cells.join(" | "));
        }
        let _ = writeln!(md, "\n| budget | scenes where AUTO beats the best peer | AUTO / best peer, range |\n|---|---:|---:|");
        for e in 3..=8 {
            let r = 10f64.powi(e);
            let ratios: Vec<f64> = results
                .iter()
                .enumerate()
                .filter(|(_, m)| !m.peers.is_empty())
                .map(|(i, m)| {
                    let best = m
                        .peers
                        .iter()
                        .map(|p| (p.build_ns + r * p.ray_ns) * 1e-9)
                        .fold(f64::INFINITY, f64::min);
                    at(i, r).auto_known / best
                })
                .collect();
            let wins = ratios.iter().filter(|&&q| q < 1.0).count();
            let lo = ratios.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = ratios.iter().copied().fold(0.0, f64::max);
            let _ = writeln!(
                md,
                "| 10^{e} | {wins} of {} | {lo:.2}–{hi:.2} |",
                ratios.len()
            );
        }
    }
    embree_best_section(&mut md, results, &at);
    md
}

/// AUTO (known budget) against Embree's best build quality (LOW or MEDIUM) at 10⁴ and 10⁵ rays on
/// the scenes above 50 000 triangles, and the grid's build against Embree LOW's there (issue 13's
/// goals).
fn embree_best_section(md: &mut String, results: &[Measured], at: &dyn Fn(usize, f64) -> Totals) {
    let embree = |m: &Measured, label: &str| {
        m.peers
            .iter()
            .find(|p| p.label == label)
            .map(|p| (p.build_ns, p.ray_ns))
    };
    let large: Vec<usize> = (0..results.len())
        .filter(|&i| results[i].triangles > 50_000)
        .filter(|&i| {
            embree(&results[i], "Embree LOW").is_some()
                && embree(&results[i], "Embree MEDIUM").is_some()
        })
        .collect();
    if large.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "## AUTO against Embree's best, scenes above 50 000 triangles\n\nAUTO's total (known \
         budget: grid build, sample rays, the choice, the rays) over the better of Embree LOW and \
         MEDIUM (build + the same rays), and the grid's build time (`UniformGrid::build`, the mesh \
         already validated) over Embree LOW's.\n"
    );
    let _ = writeln!(md, "| scene | N | AUTO / Embree best, 10⁴ | 10⁵ | grid build / Embree LOW |\n|---|---:|---:|---:|---:|");
    let mut wins = [0usize; 2];
    let mut builds = Vec::new();
    for &i in &large {
        let m = &results[i];
        let (lo, me) = (
            embree(m, "Embree LOW").unwrap_or_default(),
            embree(m, "Embree MEDIUM").unwrap_or_default(),
        );
        let mut cells = Vec::new();
        for (k, r) in [1e4, 1e5].into_iter().enumerate() {
            let best = ((lo.0 + r * lo.1).min(me.0 + r * me.1)) * 1e-9;
            let q = at(i, r).auto_known / best;
            wins[k] += usize::from(q <= 1.0);
            cells.push(format!("{q:.2}"));
        }
        let b = m.obs.grid_build_ns / lo.0;
        builds.push(b);
        let _ = writeln!(
            md,
            "| {} | {} | {} | {:.2} |",
            m.name,
            m.triangles,
            cells.join(" | "),
            b
        );
    }
    let _ = writeln!(
        md,
        "\nAUTO ≤ Embree's best on {} of {} scenes at 10⁴ rays and {} of {} at 10⁵; grid build / \
         Embree LOW: median {:.2} (range {:.2}–{:.2}).\n",
        wins[0],
        large.len(),
        wins[1],
        large.len(),
        median(&mut builds.clone()),
        builds.iter().copied().fold(f64::INFINITY, f64::min),
        builds.iter().copied().fold(0.0, f64::max)
    );
}
