//! Issue 14's interior case, timed: an ambient-occlusion renderer with the camera inside the
//! cathedral (sibenik), `expected_rays` its whole budget, the library's own sample rays; AUTO's
//! total time (build, primary rays, `update`, occlusion rays) against the grid's and the
//! kd-tree's, each built through `Scene` as a renderer would.

use std::fmt::Write as _;

use glam::Vec3;
use rayq::select::calibration::Calibration;
use rayq::select::measure::thread_seconds;
use rayq::workload::SplitMix64;
use rayq::{BuildOptions, Ray, Scene, Structure};

/// The camera: inside the nave, looking along it.
const EYE: [f32; 3] = [-14.0, -9.0, 0.0];
const WIDTH: usize = 640;
const HEIGHT: usize = 480;

/// Primary rays of the image and `ao` occlusion rays (length 4, cosine-like about the normal)
/// per hit, the hits found on the grid.
fn workload(m: &rayq::mesh::MeshData, ao: usize) -> (Vec<Ray>, Vec<Ray>) {
    let eye = Vec3::from(EYE);
    let primary: Vec<Ray> = (0..HEIGHT)
        .flat_map(|j| (0..WIDTH).map(move |i| (i, j)))
        .map(|(i, j)| {
            let x = (i as f32 + 0.5) / WIDTH as f32 * 2.0 - 1.0;
            let y = 1.0 - (j as f32 + 0.5) / HEIGHT as f32 * 2.0;
            Ray::new(eye, Vec3::new(1.0, y * 0.75, x))
        })
        .collect();
    let grid = BuildOptions {
        structure: Structure::Grid,
        ..BuildOptions::DEFAULT
    };
    let scene =
        Scene::build(&m.as_source(), &grid, Calibration::builtin()).expect("sibenik builds");
    let mut rng = SplitMix64::new(5);
    let mut occlusion = Vec::new();
    for r in &primary {
        let hit = scene.intersect(r);
        let Some(t) = hit
            .is_hit()
            .then(|| scene.mesh().triangle(hit.prim))
            .flatten()
        else {
            continue;
        };
        let mut n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
        if n.dot(r.dir) > 0.0 {
            n = -n;
        }
        let p = r.org + hit.t * r.dir;
        for _ in 0..ao {
            let mut d = rng.unit_vector();
            if d.dot(n) < 0.0 {
                d = -d;
            }
            occlusion.push(Ray::segment(p, d + n, 1e-3, 4.0));
        }
    }
    (primary, occlusion)
}

/// One run through `Scene` with `structure`: total seconds, and what it held at the end.
fn run(
    m: &rayq::mesh::MeshData,
    structure: Structure,
    primary: &[Ray],
    occlusion: &[Ray],
) -> (f64, Structure, [f64; 2]) {
    let options = BuildOptions {
        structure,
        expected_rays: (primary.len() + occlusion.len()) as u64,
        ..BuildOptions::DEFAULT
    };
    let t0 = thread_seconds();
    let mut scene =
        Scene::build(&m.as_source(), &options, Calibration::builtin()).expect("sibenik builds");
    let from_samples = scene.report().break_even_rays;
    let mut sum = 0u64;
    for r in primary {
        sum = sum.wrapping_add(u64::from(scene.intersect(r).prim));
    }
    scene
        .update(primary.len() as u64, occlusion.len() as u64)
        .expect("update");
    for r in occlusion {
        sum = sum.wrapping_add(u64::from(scene.occluded(r)));
    }
    std::hint::black_box(sum);
    let t = thread_seconds() - t0;
    let report = scene.report();
    (t, report.structure, [from_samples, report.break_even_rays])
}

/// Seconds to build a scene with `structure` alone (no rays): the build that a total includes.
fn build_seconds(m: &rayq::mesh::MeshData, structure: Structure, rays: u64) -> f64 {
    let options = BuildOptions {
        structure,
        expected_rays: rays,
        ..BuildOptions::DEFAULT
    };
    let t0 = thread_seconds();
    let scene =
        Scene::build(&m.as_source(), &options, Calibration::builtin()).expect("sibenik builds");
    let t = thread_seconds() - t0;
    drop(std::hint::black_box(scene));
    t
}

/// Seconds to copy and validate the mesh alone (the part of a scene's build that is not a
/// structure's).
fn mesh_seconds(m: &rayq::mesh::MeshData) -> f64 {
    let t0 = thread_seconds();
    let mesh = rayq::TriMesh::from_source(&m.as_source(), &mut rayq::MemoryBudget::new(0))
        .expect("sibenik's mesh");
    let t = thread_seconds() - t0;
    drop(std::hint::black_box(mesh));
    t
}

/// The section, or `None` without `../shared/scenes/sibenik.obj`.
pub fn section(repeats: usize) -> Option<String> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/scenes/sibenik.obj");
    let m = rayq::obj::load_obj(std::path::Path::new(path)).ok()?;
    let mut md = String::new();
    let _ = writeln!(
        md,
        "\n## Interior camera (sibenik)\n\nThe camera inside the nave ({WIDTH} × {HEIGHT} primary \
         rays), occlusion rays of length 4 from every hit, `expected_rays` the whole budget, the \
         library's own sample rays (its view of the whole box from outside), `rq_scene_update` \
         after the primary rays; each structure built through `Scene`, total thread CPU time \
         (build, rays, update), medians of {repeats}. W* measured: the kd-tree's build (its \
         scene's build less the mesh's copy, each timed alone) over the difference of the two \
         structures' time per ray on this workload (each total less its scene's build); W* from the \
         samples: AUTO's estimate at the build (issue 14 asks for its error apart); at the end: \
         after `rq_scene_update`, from the tapped primary rays once it has measured them.\n"
    );
    let _ = writeln!(
        md,
        "| occlusion rays per hit | rays | grid ms | kd-tree ms | AUTO ms | AUTO holds | W* from the samples | AUTO's W* at the end | W* measured | the samples' W* error | AUTO / better |\n|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|"
    );
    for ao in [4usize, 16] {
        let (primary, occlusion) = workload(&m, ao);
        let mut times = [Vec::new(), Vec::new(), Vec::new()];
        let mut held = (Structure::Grid, [f64::NAN; 2]);
        for _ in 0..repeats {
            for (k, s) in [Structure::Grid, Structure::KdTree, Structure::Auto]
                .into_iter()
                .enumerate()
            {
                let (t, structure, w) = run(&m, s, &primary, &occlusion);
                times[k].push(t);
                if s == Structure::Auto {
                    held = (structure, w);
                }
            }
        }
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let [g, k, a] = times.map(|mut v| med(&mut v));
        let rays = (primary.len() + occlusion.len()) as u64;
        let mut builds = [Vec::new(), Vec::new(), Vec::new()];
        for _ in 0..repeats {
            for (b, s) in builds.iter_mut().zip([Structure::Grid, Structure::KdTree]) {
                b.push(build_seconds(&m, s, rays));
            }
            builds[2].push(mesh_seconds(&m));
        }
        let [bg, bk, mesh] = builds.map(|mut v| med(&mut v));
        let saved_per_ray = ((g - bg) - (k - bk)) / rays as f64;
        let w_measured = if saved_per_ray > 0.0 {
            (bk - mesh) / saved_per_ray
        } else {
            f64::INFINITY
        };
        let _ = writeln!(
            md,
            "| {ao} | {rays} | {:.0} | {:.0} | {:.0} | {:?} | {:.3e} | {:.3e} | {:.3e} | {:.0} % | {:.3} |",
            g * 1e3,
            k * 1e3,
            a * 1e3,
            held.0,
            held.1[0],
            held.1[1],
            w_measured,
            100.0 * rayq::select::validate::relative_error(held.1[0], w_measured),
            a / g.min(k)
        );
    }
    Some(md)
}
