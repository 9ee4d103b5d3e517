//! A query's fixed cost: a scene of one triangle, where every structure is a single leaf or cell,
//! and three sets of rays from above it — rays that hit it, rays that enter its box and miss it,
//! and rays that miss its box. What a structure spends on them is what it spends on any query
//! besides its walk (`examples/raycost.rs floor`, `examples/evaluate`).

use rayq::accel::RayQuery;
use rayq::mesh::MeshData;
use rayq::select::measure::median_ns;
use rayq::workload::SplitMix64;
use rayq::{GridParams, KdTree, KdTreeParams, MemoryBudget, Ray, TriMesh, UniformGrid};

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

/// What one set of rays costs: ns per ray on the kd-tree, the grid and (built with the peers)
/// Embree 3 MEDIUM's `rtcIntersect1`.
pub struct Cost {
    pub what: &'static str,
    pub kd: f64,
    pub grid: f64,
    pub embree: Option<f64>,
}

/// Each set's cost on the one-triangle scene (default parameters), thread CPU time, medians of
/// `repeats`; empty if the scene cannot be built.
pub fn measure(repeats: u32) -> Vec<Cost> {
    let data = scene();
    let Ok(mesh) = TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)) else {
        return Vec::new();
    };
    let (Ok(tree), Ok(grid)) = (
        KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)),
        UniformGrid::build(&mesh, &GridParams::DEFAULT, &mut MemoryBudget::new(0)),
    ) else {
        return Vec::new();
    };
    #[cfg(feature = "peers")]
    let device = crate::peer_structures::EmbreeDevice::new().ok();
    #[cfg(feature = "peers")]
    let embree = crate::peer_structures::Kind::Embree(
        crate::peer_structures::embree3::RTC_BUILD_QUALITY_MEDIUM,
    )
    .build(&data, device.as_ref())
    .ok();
    ray_sets()
        .into_iter()
        .map(|(what, rays)| {
            let n = rays.len() as f64;
            let per_ray = |accel: &dyn RayQuery| {
                median_ns(repeats, || {
                    rays.iter()
                        .filter(|r| accel.intersect(&mesh, r).is_hit())
                        .count()
                })
                .0 / n
            };
            #[cfg(feature = "peers")]
            let embree = embree
                .as_ref()
                .map(|b| median_ns(repeats, || b.count_hits(&rays)).0 / n);
            #[cfg(not(feature = "peers"))]
            let embree = None;
            Cost {
                what,
                kd: per_ray(&tree),
                grid: per_ray(&grid),
                embree,
            }
        })
        .collect()
}
