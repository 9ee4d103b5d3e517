//! A query's fixed cost: a scene of one triangle, where every structure is a single leaf or cell,
//! and three sets of rays from above it — rays that hit it, rays that enter its box and miss it,
//! and rays that miss its box. What a structure spends on them is what it spends on any query
//! besides its walk (`examples/raycost.rs floor`, `examples/evaluate`).

use rayq::mesh::MeshData;
use rayq::workload::SplitMix64;
use rayq::Ray;

/// Rays in each set.
pub const RAYS: usize = 100_000;

/// The triangle (0,0,0), (1,0,0), (0,1,0).
pub fn scene() -> MeshData {
    MeshData {
        vertices: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![[0, 1, 2]],
    }
}

/// The three sets, named: origins above the triangle's lower half, aimed at it, at its box past
/// the hypotenuse, and (moved aside) at a point three units away.
pub fn ray_sets() -> [(&'static str, Vec<Ray>); 3] {
    let mut rng = SplitMix64::new(11);
    let aimed =
        |origin: glam::Vec3, target: glam::Vec3| Ray::new(origin, (target - origin).normalize());
    let (mut hit, mut inside, mut outside) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..RAYS {
        let o = glam::Vec3::new(
            0.5 * rng.next_f32(),
            0.5 * rng.next_f32(),
            1.0 + rng.next_f32(),
        );
        let (a, b) = (0.5 * rng.next_f32(), 0.5 * rng.next_f32());
        hit.push(aimed(o, glam::Vec3::new(a, b, 0.0)));
        inside.push(aimed(o, glam::Vec3::new(1.0 - 0.3 * a, 1.0 - 0.3 * b, 0.0)));
        outside.push(aimed(
            o + glam::Vec3::new(3.0, 0.0, 0.0),
            glam::Vec3::new(3.0 + a, b, 0.0),
        ));
    }
    [
        ("hit the triangle", hit),
        ("enter its box, miss it", inside),
        ("miss its box", outside),
    ]
}
