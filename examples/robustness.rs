//! The figures of docs/robustness.md: build time, bytes, references per triangle and rays/s per
//! structure, and what the selector picks, for the failure-mode scenes.
//!
//!     cargo run --release --example robustness -- stats <scene>...
//!     cargo run --release --example robustness -- grid-once <scene>     (for callgrind)
//!
//! A scene is an OBJ path, `proc:<name>:<tris>` (rayq::procedural::by_name) or `case:<name>` (the
//! failure-mode scenes of tests/robustness.rs).
use rayq::accel::RayQuery;
use rayq::mesh::MeshData;
use rayq::workload::{camera_rays, SplitMix64};
use rayq::*;
use std::time::Instant;

fn scene(spec: &str) -> MeshData {
    if let Some(rest) = spec.strip_prefix("proc:") {
        let (name, n) = rest.split_once(':').unwrap();
        return procedural::by_name(name, n.parse().unwrap()).unwrap();
    }
    if let Some(name) = spec.strip_prefix("case:") {
        return case(name);
    }
    rayq::obj::load_obj(spec).unwrap()
}

fn case(name: &str) -> MeshData {
    match name {
        "duplicates" => {
            let mut d = procedural::closed_sphere(16);
            let c = d.clone();
            d.append(&c);
            d.append(&c);
            d
        }
        "coplanar" => {
            let mut d = MeshData::default();
            for k in 0..2000 {
                let s = 0.1 + (k % 37) as f32 * 0.02;
                let o = (k % 91) as f32 * 0.01;
                d.push_quad([
                    [o, o, 0.0],
                    [o + s, o, 0.0],
                    [o, o + s, 0.0],
                    [o + s, o + s, 0.0],
                ]);
            }
            d
        }
        "sheets" => {
            let mut d = MeshData::default();
            for k in 0..=16 {
                let x = k as f32 / 16.0;
                d.push_quad([[x, 0.0, 0.0], [x, 1.0, 0.0], [x, 0.0, 1.0], [x, 1.0, 1.0]]);
                d.push_quad([[0.0, x, 0.0], [1.0, x, 0.0], [0.0, x, 1.0], [1.0, x, 1.0]]);
            }
            d
        }
        "closed" => procedural::closed_sphere(40),
        "one" => MeshData {
            vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            indices: vec![[0, 1, 2]],
        },
        "two" => {
            let mut d = MeshData::default();
            d.push_quad([
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1.0, 1.0, 0.0],
            ]);
            d
        }
        "huge" => procedural::closed_sphere(40).transformed(1.0, [1e7, -1e7, 1e7]),
        "tiny" => procedural::closed_sphere(40).transformed(1e-6, [0.0; 3]),
        "onecell" => {
            let mut d = procedural::random_soup(5000, 11, 0.01).transformed(1e-3, [0.5; 3]);
            d.append(&MeshData {
                vertices: vec![
                    [-10.0, -10.0, -10.0],
                    [10.0, -10.0, -10.0],
                    [-10.0, 10.0, 10.0],
                ],
                indices: vec![[0, 1, 2]],
            });
            d
        }
        _ => panic!("unknown case {name}"),
    }
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn time<T>(runs: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut out = None;
    let mut ts = Vec::new();
    for _ in 0..runs {
        let t = Instant::now();
        out = Some(f());
        ts.push(t.elapsed().as_secs_f64());
    }
    (median(ts), out.unwrap())
}

fn rays_per_second(accel: &dyn RayQuery, mesh: &TriMesh, rays: &[Ray]) -> (f64, usize) {
    let (t, hits) = time(3, || {
        rays.iter()
            .filter(|r| accel.intersect(mesh, r).is_hit())
            .count()
    });
    (rays.len() as f64 / t, hits)
}

fn stats(spec: &str) {
    let data = scene(spec);
    let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
    let live = (mesh.len() - mesh.degenerate_count()).max(1) as f64;
    let runs = if mesh.len() > 50_000 { 1 } else { 5 };
    let (gb, grid) = time(runs, || {
        UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap()
    });
    let (kb, kd) = time(runs, || {
        KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap()
    });
    let rays = camera_rays(&mesh.bounds(), 256, &mut SplitMix64::new(1));
    let (gr, gh) = rays_per_second(&grid, &mesh, &rays);
    let (kr, kh) = rays_per_second(&kd, &mesh, &rays);
    assert_eq!(gh, kh);
    println!(
        "{spec}: tris {} | grid res {:?} build {:.2} ms refs/tri {:.2} bytes {} {:.2} Mrays/s | kd build {:.2} ms refs/tri {:.2} bytes {} nodes {} depth {} largest leaf {} budget leaves {:?} {:.2} Mrays/s | hits {gh}/{}",
        mesh.len(),
        grid.resolution(),
        gb * 1e3,
        grid.reference_count() as f64 / live,
        grid.memory_bytes() + mesh.memory_bytes(),
        gr * 1e-6,
        kb * 1e3,
        kd.reference_count() as f64 / live,
        kd.memory_bytes() + mesh.memory_bytes(),
        kd.node_count(),
        kd.depth(),
        kd.largest_leaf(),
        kd.budget_leaves(),
        kr * 1e-6,
        rays.len()
    );
    for expected in [1_000_000u64, 100_000_000] {
        let options = BuildOptions {
            expected_rays: expected,
            ..BuildOptions::DEFAULT
        };
        let (ab, s) = time(1, || {
            Scene::build(&data.as_source(), &options, Calibration::builtin()).unwrap()
        });
        let r = s.report();
        println!(
            "    auto expected {expected:e}: {:?} {:?} W* {:.3e} est grid {:.1} ns/ray kd {:.1} ns/ray kd build {:.2} ms | bytes {} refs/tri {:.2} | build+select {:.2} ms",
            r.structure,
            r.outcome,
            r.break_even_rays,
            r.grid_ray_seconds * 1e9,
            r.kd_ray_seconds * 1e9,
            r.kd_build_seconds * 1e3,
            r.memory_bytes,
            r.references_per_triangle,
            ab * 1e3
        );
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args[0].as_str() {
        "stats" => args[1..].iter().for_each(|s| stats(s)),
        "grid-once" => {
            let data = scene(&args[1]);
            let mesh = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
            let g =
                UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
            println!("refs {}", g.reference_count());
        }
        "refs" => {
            // Every grid's reference count, to compare before/after bit for bit.
            for s in &args[1..] {
                let data = scene(s);
                let mesh =
                    TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
                for p in [GridParams::DEFAULT, GridParams::COARSE, GridParams::FINE] {
                    let g = UniformGrid::build(&mesh, &p, &mut MemoryBudget::new(0)).unwrap();
                    println!("{s} {} refs {}", p.density, g.reference_count());
                }
            }
        }
        _ => panic!("stats | grid-once | refs"),
    }
}
