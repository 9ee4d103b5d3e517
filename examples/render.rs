//! Renders an OBJ scene (or a procedural one) to a PPM image with one primary ray per pixel and
//! headlight shading, and prints how the scene was built and how fast the rays went.
//!
//!     cargo run --release --example render -- scenes/teapot.obj teapot.ppm [width] [grid|auto]
//!     cargo run --release --example render -- procedural:sphereflake:100000 flake.ppm

use std::io::Write;
use std::time::Instant;

use glam::Vec3;
use rayq::mesh::MeshData;
use rayq::{BuildOptions, Calibration, Hit, Ray, Scene, Structure};

fn load(spec: &str) -> Result<MeshData, String> {
    if let Some(rest) = spec.strip_prefix("procedural:") {
        let (name, tris) = rest.split_once(':').unwrap_or((rest, "100000"));
        let tris = tris
            .parse()
            .map_err(|_| format!("bad triangle count in {spec}"))?;
        return rayq::procedural::by_name(name, tris)
            .ok_or_else(|| format!("unknown scene {name}"));
    }
    Ok(rayq::obj::load_obj(spec)?)
}

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() < 3 {
        return Err(
            "usage: render SCENE.obj|procedural:NAME:TRIS OUT.ppm [width] [grid|kdtree|auto]"
                .into(),
        );
    }
    let width: usize = args
        .get(3)
        .map_or(Ok(640), |w| w.parse())
        .map_err(|_| "bad width")?;
    let height = width * 3 / 4;
    let structure = match args.get(4).map(String::as_str) {
        None | Some("auto") => Structure::Auto,
        Some("grid") => Structure::Grid,
        Some("kdtree") => Structure::KdTree,
        Some(other) => return Err(format!("unknown structure {other}")),
    };

    let data = load(&args[1])?;
    let start = Instant::now();
    let options = BuildOptions {
        structure,
        expected_rays: (width * height) as u64,
        ..BuildOptions::DEFAULT
    };
    let scene = Scene::build(&data.as_source(), &options, Calibration::builtin())
        .map_err(|e| e.to_string())?;
    let build = start.elapsed();

    // A camera on the box diagonal looking at the centre, 45° vertical field of view.
    let b = scene.mesh().bounds();
    let center = 0.5 * (b.min + b.max);
    let eye = center + Vec3::new(0.62, -0.55, 0.45) * b.extent().length();
    let forward = (center - eye).normalize();
    let up_hint = if forward.z.abs() > 0.9 {
        Vec3::Y
    } else {
        Vec3::Z
    };
    let right = forward.cross(up_hint).normalize();
    let up = right.cross(forward);
    let half = (22.5f32).to_radians().tan();
    let aspect = width as f32 / height as f32;

    let start = Instant::now();
    let mut hits = vec![Hit::MISS; width * height];
    for (i, hit) in hits.iter_mut().enumerate() {
        let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
        let sx = (2.0 * x / width as f32 - 1.0) * half * aspect;
        let sy = (1.0 - 2.0 * y / height as f32) * half;
        *hit = scene.intersect(&Ray::new(eye, forward + sx * right + sy * up));
    }
    let trace = start.elapsed();

    let mut image = Vec::with_capacity(width * height * 3);
    for (i, hit) in hits.iter().enumerate() {
        let shade = match scene.mesh().triangle(hit.prim) {
            Some(t) => {
                let (x, y) = ((i % width) as f32 + 0.5, (i / width) as f32 + 0.5);
                let dir = (forward
                    + (2.0 * x / width as f32 - 1.0) * half * aspect * right
                    + (1.0 - 2.0 * y / height as f32) * half * up)
                    .normalize();
                let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
                0.15 + 0.85 * n.dot(dir).abs()
            }
            None => 0.0,
        };
        let v = (shade * 255.0) as u8;
        image.extend([v, v, (shade * 0.9 * 255.0 + 20.0).min(255.0) as u8]);
    }
    let mut file = std::fs::File::create(&args[2]).map_err(|e| format!("{}: {e}", args[2]))?;
    write!(file, "P6\n{width} {height}\n255\n").map_err(|e| e.to_string())?;
    file.write_all(&image).map_err(|e| e.to_string())?;

    let r = scene.report();
    let rays = (width * height) as f64;
    println!(
        "scene: {} triangles ({} degenerate)",
        r.triangle_count,
        scene.mesh().degenerate_count()
    );
    println!(
        "structure: {:?} ({:?}), grid {:?}, {:.2} refs/triangle, {:.1} MiB",
        r.structure,
        r.outcome,
        r.grid_resolution,
        r.references_per_triangle,
        r.memory_bytes as f64 / (1024.0 * 1024.0)
    );
    println!("build: {:.2} ms", build.as_secs_f64() * 1e3);
    println!(
        "trace: {:.2} ms for {} rays ({:.2} Mrays/s)",
        trace.as_secs_f64() * 1e3,
        rays,
        rays / trace.as_secs_f64() / 1e6
    );
    println!("wrote {}", args[2]);
    Ok(())
}
