//! Renders an OBJ scene (or a procedural one) to a PNG (or PPM) image with one primary ray per pixel
//! and headlight shading, and prints how the scene was built and how fast the rays went.
//!
//!     cargo run --release --example render -- scenes/teapot.obj teapot.png [width] [grid|kdtree|auto] [--up AXIS]
//!     cargo run --release --example render -- procedural:sphereflake:100000 flake.png
//!
//! The image format follows the output's extension (`.png` or `.ppm`). The camera stands in front of
//! the scene, to the right and above, with the up axis up: `--up x|y|z` (or `-x`, `-y`, `-z`) says
//! which axis that is; without it, OBJ files are taken as Y-up (the Wavefront convention, what
//! Blender and Maya export) and procedural scenes as Z-up (the SPD convention they follow).

use std::io::{BufWriter, Write};
use std::time::Instant;

use glam::Vec3;
use rayq::mesh::MeshData;
use rayq::{BuildOptions, Calibration, Hit, Ray, Scene, Structure};

const USAGE: &str = "usage: render SCENE.obj|procedural:NAME:TRIS OUT.png|OUT.ppm [width] \
                     [grid|kdtree|auto] [--up x|y|z|-x|-y|-z]";

/// What the command line asked for.
struct Args {
    scene: String,
    out: String,
    width: usize,
    structure: Structure,
    /// `None`: the scene's convention (see the module documentation).
    up: Option<Vec3>,
}

fn parse_axis(s: &str) -> Option<Vec3> {
    let (sign, name) = match s.strip_prefix('-') {
        Some(rest) => (-1.0, rest),
        None => (1.0, s.strip_prefix('+').unwrap_or(s)),
    };
    let axis = match name {
        "x" | "X" => Vec3::X,
        "y" | "Y" => Vec3::Y,
        "z" | "Z" => Vec3::Z,
        _ => return None,
    };
    Some(sign * axis)
}

fn axis_name(axis: Vec3) -> String {
    let sign = if axis.min_element() < 0.0 { '-' } else { '+' };
    let name = ["x", "y", "z"][axis.abs().max_position()];
    format!("{sign}{name}")
}

fn parse_args(mut raw: Vec<String>) -> Result<Args, String> {
    let mut up = None;
    if let Some(at) = raw.iter().position(|a| a == "--up") {
        let value = raw.get(at + 1).ok_or("--up needs an axis")?;
        up = Some(parse_axis(value).ok_or_else(|| format!("--up {value}: not an axis"))?);
        raw.drain(at..at + 2);
    }
    if raw.len() < 2 || raw.len() > 4 {
        return Err("wrong number of arguments".into());
    }
    let width = match raw.get(2) {
        None => 640,
        Some(w) => match w.parse() {
            Ok(w) if (1..=16384).contains(&w) => w,
            _ => return Err(format!("bad width {w}")),
        },
    };
    let structure = match raw.get(3).map(String::as_str) {
        None | Some("auto") => Structure::Auto,
        Some("grid") => Structure::Grid,
        Some("kdtree") => Structure::KdTree,
        Some(other) => return Err(format!("unknown structure {other}")),
    };
    let out = raw.swap_remove(1);
    if !(out.ends_with(".png") || out.ends_with(".ppm")) {
        return Err(format!("{out}: the output must end in .png or .ppm"));
    }
    Ok(Args {
        scene: raw.swap_remove(0),
        out,
        width,
        structure,
        up,
    })
}

/// The mesh, and the up axis its kind implies.
fn load(spec: &str) -> Result<(MeshData, Vec3, &'static str), String> {
    if let Some(rest) = spec.strip_prefix("procedural:") {
        let (name, tris) = rest.split_once(':').unwrap_or((rest, "100000"));
        let tris = tris
            .parse()
            .map_err(|_| format!("bad triangle count in {spec}"))?;
        let mesh =
            rayq::procedural::by_name(name, tris).ok_or_else(|| format!("unknown scene {name}"))?;
        return Ok((mesh, Vec3::Z, "procedural scenes are Z-up"));
    }
    let mesh = rayq::obj::load_obj(spec)?;
    Ok((mesh, Vec3::Y, "OBJ files are Y-up by convention"))
}

/// A pinhole camera with a 45° vertical field of view.
struct Camera {
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    /// tan(fov / 2) times the aspect ratio, and tan(fov / 2).
    half: (f32, f32),
    size: (usize, usize),
}

impl Camera {
    /// Looks at the centre of `bounds` from in front, to the right and above, `up` being up. For a
    /// Z-up scene "in front" is −Y, the view Blender calls front; every other axis gets the same view
    /// rotated so that its up is up.
    fn framing(bounds: &rayq::Aabb, up: Vec3, size: (usize, usize)) -> Camera {
        let center = 0.5 * (bounds.min + bounds.max);
        // For up = ±Z, right = X; for up = ±Y, also X (then toward the viewer is +Z, the OpenGL
        // convention); for up = ±X, Y.
        let right_axis = if up.x != 0.0 { Vec3::Y } else { Vec3::X };
        let toward_viewer = right_axis.cross(up);
        let offset = 0.62 * right_axis + 0.55 * toward_viewer + 0.45 * up;
        let eye = center + offset * bounds.extent().length().max(1e-6);
        let forward = (center - eye).normalize();
        let right = forward.cross(up).normalize();
        let tan = 22.5f32.to_radians().tan();
        Camera {
            eye,
            forward,
            right,
            up: right.cross(forward),
            half: (tan * size.0 as f32 / size.1 as f32, tan),
            size,
        }
    }

    /// The direction through the centre of pixel `i` (row-major, top row first).
    fn direction(&self, i: usize) -> Vec3 {
        let (w, h) = (self.size.0 as f32, self.size.1 as f32);
        let (x, y) = (
            (i % self.size.0) as f32 + 0.5,
            (i / self.size.0) as f32 + 0.5,
        );
        let sx = (2.0 * x / w - 1.0) * self.half.0;
        let sy = (1.0 - 2.0 * y / h) * self.half.1;
        self.forward + sx * self.right + sy * self.up
    }
}

/// Two-sided Lambert under a headlight, on a dark blue background.
fn shade(scene: &Scene, hit: &Hit, dir: Vec3) -> [u8; 3] {
    let shade = match scene.mesh().triangle(hit.prim) {
        Some(t) => {
            let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero();
            0.15 + 0.85 * n.dot(dir.normalize()).abs()
        }
        None => 0.0,
    };
    let v = (shade * 255.0) as u8;
    [v, v, (shade * 0.9 * 255.0 + 20.0).min(255.0) as u8]
}

fn write_image(path: &str, (width, height): (usize, usize), rgb: &[u8]) -> Result<(), String> {
    let err = |e: &dyn std::fmt::Display| format!("{path}: {e}");
    let file = std::fs::File::create(path).map_err(|e| err(&e))?;
    let mut out = BufWriter::new(file);
    if path.ends_with(".png") {
        let mut encoder = png::Encoder::new(&mut out, width as u32, height as u32);
        encoder.set_color(png::ColorType::Rgb);
        encoder.set_depth(png::BitDepth::Eight);
        let mut writer = encoder.write_header().map_err(|e| err(&e))?;
        writer.write_image_data(rgb).map_err(|e| err(&e))?;
        writer.finish().map_err(|e| err(&e))?;
    } else {
        write!(out, "P6\n{width} {height}\n255\n").map_err(|e| err(&e))?;
        out.write_all(rgb).map_err(|e| err(&e))?;
    }
    out.flush().map_err(|e| err(&e))
}

fn main() -> Result<(), String> {
    let args =
        parse_args(std::env::args().skip(1).collect()).map_err(|e| format!("{e}\n{USAGE}"))?;
    let size = (args.width, args.width * 3 / 4);
    let (data, conventional_up, why) = load(&args.scene)?;
    let (up, why) = match args.up {
        Some(up) => (up, "--up"),
        None => (conventional_up, why),
    };

    let start = Instant::now();
    let options = BuildOptions {
        structure: args.structure,
        expected_rays: (size.0 * size.1) as u64,
        ..BuildOptions::DEFAULT
    };
    let scene = Scene::build(&data.as_source(), &options, Calibration::builtin())
        .map_err(|e| e.to_string())?;
    let build = start.elapsed();

    let camera = Camera::framing(&scene.mesh().bounds(), up, size);
    let start = Instant::now();
    let mut hits = vec![Hit::MISS; size.0 * size.1];
    for (i, hit) in hits.iter_mut().enumerate() {
        *hit = scene.intersect(&Ray::new(camera.eye, camera.direction(i)));
    }
    let trace = start.elapsed();

    let image: Vec<u8> = hits
        .iter()
        .enumerate()
        .flat_map(|(i, hit)| shade(&scene, hit, camera.direction(i)))
        .collect();
    write_image(&args.out, size, &image)?;

    let r = scene.report();
    let rays = (size.0 * size.1) as f64;
    println!(
        "scene: {} triangles ({} degenerate), up {} ({why})",
        r.triangle_count,
        scene.mesh().degenerate_count(),
        axis_name(up)
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
    println!("wrote {} ({} x {})", args.out, size.0, size.1);
    Ok(())
}
