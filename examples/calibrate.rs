//! Fits this machine's calibration: builds both structures on every scene, times builds and a
//! path-tracer-like workload (camera rays plus one diffuse bounce per hit), fits the cost model,
//! prints how well it predicts (in-sample and leave-one-out), and writes a blob.
//!
//!     cargo run --release --example calibrate -- <scene files or dirs> [-o calib.rqcal]
//!         [--no-procedural] [--side N] [--repeats K]
//!
//! With no scene arguments it uses `scenes/`. Procedural SPD-style scenes (sphereflake, tetra,
//! mount, rings, gears, stadium, soup at 10⁴ and 10⁵ triangles, slivers at 2·10³ and 10⁴) are added unless
//! `--no-procedural`.

use std::path::{Path, PathBuf};

use rayq::mesh::MeshData;
use rayq::select::fit::{fit, Observation};
use rayq::select::measure::{observe, MeasureParams};
use rayq::select::model::Part;
use rayq::select::validate::{
    best_variant, cross_validated_break_even, cross_validated_errors, median, relative_error,
    GridCost, VARIANTS,
};
use rayq::{MemoryBudget, TriMesh};

struct Args {
    scenes: Vec<PathBuf>,
    out: PathBuf,
    /// Write the measurements here (one scene a line) to refit later without measuring.
    save: Option<PathBuf>,
    /// Fit measurements saved earlier instead of measuring.
    load: Option<PathBuf>,
    procedural: bool,
    params: MeasureParams,
    /// Fit this model variant (a name from `VARIANTS`) instead of the one with the lowest error.
    variant: Option<String>,
}

fn usage() -> ! {
    eprintln!(
        "usage: calibrate [SCENE.obj | DIR]... [-o OUT.rqcal] [--no-procedural] [--side N] [--repeats K] [--save FILE | --load FILE] [--variant NAME]"
    );
    std::process::exit(2)
}

fn parse() -> Args {
    let mut a = Args {
        scenes: Vec::new(),
        out: PathBuf::from("calib.rqcal"),
        save: None,
        load: None,
        procedural: true,
        params: MeasureParams::DEFAULT,
        variant: None,
    };
    let mut it = std::env::args().skip(1);
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "-o" => a.out = it.next().map(PathBuf::from).unwrap_or_else(|| usage()),
            "--no-procedural" => a.procedural = false,
            "--save" => a.save = Some(it.next().map(PathBuf::from).unwrap_or_else(|| usage())),
            "--load" => a.load = Some(it.next().map(PathBuf::from).unwrap_or_else(|| usage())),
            "--variant" => a.variant = Some(it.next().unwrap_or_else(|| usage())),
            "--side" => {
                a.params.workload_side = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or_else(|| usage())
            }
            "--repeats" => {
                a.params.repeats = it
                    .next()
                    .and_then(|s| s.parse().ok())
                    .unwrap_or_else(|| usage())
            }
            s if s.starts_with('-') => usage(),
            s => a.scenes.push(PathBuf::from(s)),
        }
    }
    if a.scenes.is_empty() {
        a.scenes.push(PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/scenes"
        )));
    }
    a
}

/// OBJ files named on the command line, directories expanded (sorted).
fn obj_files(paths: &[PathBuf]) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for p in paths {
        if p.is_dir() {
            let mut in_dir: Vec<PathBuf> = std::fs::read_dir(p)
                .map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).collect())
                .unwrap_or_default();
            in_dir.retain(|f| f.extension().is_some_and(|e| e == "obj"));
            in_dir.sort();
            out.extend(in_dir);
        } else {
            out.push(p.clone());
        }
    }
    out
}

/// The procedural scene set. Slivers only small: 10⁵ of them spanning the box take the grid tens of
/// seconds (every sliver crosses thousands of cells), which would dominate the run.
pub fn procedural_scenes() -> Vec<(String, MeshData)> {
    let sets: [(&str, &[usize]); 8] = [
        ("sphereflake", &[10_000, 100_000]),
        ("tetra", &[10_000, 100_000]),
        ("mount", &[10_000, 100_000]),
        ("rings", &[10_000, 100_000]),
        ("gears", &[10_000, 100_000]),
        ("stadium", &[10_000, 100_000]),
        ("soup", &[10_000, 100_000]),
        ("slivers", &[2_000, 10_000]),
    ];
    let mut v = Vec::new();
    for (name, sizes) in sets {
        for &n in sizes {
            if let Some(m) = rayq::procedural::by_name(name, n) {
                v.push((format!("{name}-{}k", n / 1000), m));
            }
        }
    }
    v
}

fn name_of(p: &Path) -> String {
    p.file_stem().map_or_else(
        || p.display().to_string(),
        |s| s.to_string_lossy().into_owned(),
    )
}

/// One observation as a line: name, then the numbers in a fixed order.
fn to_line(name: &str, o: &Observation) -> String {
    let f = |x: &rayq::select::model::SceneFeatures| {
        format!(
            "{} {} {} {} {} {}",
            x.triangles, x.rays, x.hits, x.cells, x.tests, x.grid_references
        )
    };
    format!(
        "{name} {} {} {} {} {} {} {}",
        f(&o.workload),
        f(&o.sample),
        o.grid_build_ns,
        o.kd_build_ns,
        o.grid_ray_ns,
        o.kd_ray_ns,
        o.sample_grid_ray_ns
    )
}

fn from_line(line: &str) -> Option<(String, Observation)> {
    let mut w = line.split_whitespace();
    let name = w.next()?.to_string();
    let mut feat = || -> Option<rayq::select::model::SceneFeatures> {
        Some(rayq::select::model::SceneFeatures {
            triangles: w.next()?.parse().ok()?,
            rays: w.next()?.parse().ok()?,
            hits: w.next()?.parse().ok()?,
            cells: w.next()?.parse().ok()?,
            tests: w.next()?.parse().ok()?,
            grid_references: w.next()?.parse().ok()?,
            // Not saved (the fit does not use it).
            grid_largest_cell: 0,
        })
    };
    let workload = feat()?;
    let sample = feat()?;
    let mut num = || -> Option<f64> { w.next()?.parse().ok() };
    Some((
        name,
        Observation {
            workload,
            sample,
            grid_build_ns: num()?,
            kd_build_ns: num()?,
            grid_ray_ns: num()?,
            kd_ray_ns: num()?,
            sample_grid_ray_ns: num()?,
        },
    ))
}

fn main() {
    let args = parse();
    let obs = match &args.load {
        Some(path) => {
            let text = std::fs::read_to_string(path).unwrap_or_else(|e| {
                eprintln!("cannot read {}: {e}", path.display());
                std::process::exit(1)
            });
            text.lines().filter_map(from_line).collect()
        }
        None => measure(&args),
    };
    if let Some(path) = &args.save {
        let text: String = obs.iter().map(|(n, o)| to_line(n, o) + "\n").collect();
        if let Err(e) = std::fs::write(path, text) {
            eprintln!("cannot write {}: {e}", path.display());
        }
    }
    report_and_write(&args, &obs);
}

fn measure(args: &Args) -> Vec<(String, Observation)> {
    let mut scenes: Vec<(String, MeshData)> = Vec::new();
    for path in obj_files(&args.scenes) {
        match rayq::obj::load_obj(&path) {
            Ok(m) => scenes.push((name_of(&path), m)),
            Err(e) => eprintln!("skipping {}: {e}", path.display()),
        }
    }
    if args.procedural {
        scenes.extend(procedural_scenes());
    }
    if scenes.len() < 3 {
        eprintln!(
            "need at least 3 scenes to fit and cross-validate, have {}",
            scenes.len()
        );
        std::process::exit(1);
    }
    println!(
        "measuring {} scenes ({}² camera rays + bounces, median of {})",
        scenes.len(),
        args.params.workload_side,
        args.params.repeats
    );
    println!(
        "{:>3} {:<18} {:>8} {:>9} {:>9} {:>8} {:>8} {:>11}",
        "#", "scene", "N", "grid ms", "kd ms", "grid ns", "kd ns", "W* meas"
    );
    let mut obs = Vec::new();
    for (i, (name, data)) in scenes.iter().enumerate() {
        let mesh = match TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("skipping {name}: {e}");
                continue;
            }
        };
        match observe(&mesh, &args.params) {
            Ok(o) => {
                println!(
                    "{:>3} {:<18} {:>8} {:>9.2} {:>9.1} {:>8.0} {:>8.0} {:>11.3e}",
                    i + 1,
                    name,
                    mesh.len(),
                    o.grid_build_ns * 1e-6,
                    o.kd_build_ns * 1e-6,
                    o.grid_ray_ns,
                    o.kd_ray_ns,
                    o.measured_break_even()
                );
                obs.push((name.clone(), o));
            }
            Err(e) => eprintln!("skipping {name}: {e}"),
        }
    }
    obs
}

fn report_and_write(args: &Args, obs: &[(String, Observation)]) {
    let obs = obs.to_vec();
    if obs.len() < 3 {
        eprintln!(
            "need at least 3 scenes to fit and cross-validate, have {}",
            obs.len()
        );
        std::process::exit(1);
    }
    let all: Vec<Observation> = obs.iter().map(|o| o.1).collect();
    // Model variants: a term stays only if it lowers the cross-validated W* error; the best is the
    // one written.
    println!("\nleave-one-out W* error (predicted from the selector's sample rays), by model:");
    for (label, terms) in VARIANTS {
        let mut errs = cross_validated_errors(&all, &terms, 0, GridCost::Counted);
        let max = errs.iter().copied().fold(0.0, f64::max);
        println!(
            "  {label:<24} median {:>6.1} %  max {:>7.1} %",
            100.0 * median(&mut errs),
            100.0 * max
        );
    }
    let (chosen, terms) = match &args.variant {
        Some(name) => match VARIANTS.iter().find(|(label, _)| label == name) {
            Some(&(label, terms)) => (label, terms),
            None => {
                eprintln!("no model variant named {name:?}");
                std::process::exit(2)
            }
        },
        None => {
            let (label, terms, _) = best_variant(&all);
            (label, terms)
        }
    };
    let mut errs = cross_validated_errors(&all, &terms, 0, GridCost::Clock);
    let max = errs.iter().copied().fold(0.0, f64::max);
    println!(
        "  {:<24} median {:>6.1} %  max {:>7.1} %",
        format!("{chosen}, grid by clock"),
        100.0 * median(&mut errs),
        100.0 * max
    );
    println!("chosen: {chosen}");

    let calib = match fit(&all, &terms, 0) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("fit failed: {e:?}");
            std::process::exit(1);
        }
    };
    println!("\nfitted constants (ns):");
    for (c, v) in rayq::select::calibration::CONSTANTS
        .iter()
        .zip(calib.values())
    {
        println!("  {:<30} {:>12.4}", c.name, v);
    }
    println!("\nin-sample fit, relative error per part (median / max):");
    for part in Part::ALL {
        let mut errs: Vec<f64> = all
            .iter()
            .map(|o| relative_error(part.predict(&calib, &o.workload), o.measured(part)))
            .collect();
        let max = errs.iter().copied().fold(0.0, f64::max);
        println!(
            "  {:<10} {:>6.1} % / {:>6.1} %",
            format!("{part:?}"),
            100.0 * median(&mut errs),
            100.0 * max
        );
    }
    println!("\nper scene ({chosen}, leave-one-out):");
    let est = cross_validated_break_even(&all, &terms, 0, GridCost::Counted);
    for ((name, o), est) in obs.iter().zip(est) {
        println!(
            "  {name:<18} W* meas {:>11.3e}  est {:>11.3e}  error {:>6.1} %",
            o.measured_break_even(),
            est,
            100.0 * relative_error(est, o.measured_break_even())
        );
    }

    let mut blob = [0u8; rayq::select::calibration::BLOB_LEN];
    let len = calib.to_bytes(&mut blob).expect("blob fits");
    if let Err(e) = std::fs::write(&args.out, &blob[..len]) {
        eprintln!("cannot write {}: {e}", args.out.display());
        std::process::exit(1);
    }
    println!("\nwrote {} ({len} bytes)", args.out.display());
}
