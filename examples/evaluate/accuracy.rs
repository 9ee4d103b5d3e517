//! Hit accuracy against the exact answer: which structures and peers answer every ray exactly, and
//! which let rays aimed at vertices and edges of closed meshes slip through.
//!
//! The reference is rayq's brute force: its triangle test is the exact one (tested against an
//! integer-arithmetic definition in src/triangle/tests.rs), tried on every triangle. A structure's
//! or peer's answer for a ray is judged by the triangle it names, with the exact test:
//! - wrong: it names no triangle where the exact answer hits, names one where nothing is hit, or
//!   names a triangle the exact test does not hit at the reference's nearest `t` (a tie at the same
//!   `t`, as at a shared edge, is right);
//! - leak (closed meshes only; rays aimed from outside at a vertex or an edge midpoint, target at
//!   `t = 1`, that cross the surface there transversally): the exact answer hits at or before the
//!   target, but the structure reports a miss or a hit beyond it (by its own `t`: naming the
//!   neighbour of the exact triangle at the target is wrong, not a leak). Rays that graze a
//!   silhouette are left out, as rqcheck's `watertight` mode leaves them out.

use std::collections::{HashMap, HashSet};

use glam::Vec3;
use rayq::accel::RayQuery;
use rayq::triangle::PreparedRay;
use rayq::workload::SplitMix64;
use rayq::{BruteForce, Hit, Ray, TriMesh};

/// The rays the accuracy check traces: a sample of the workload (camera rays and bounces), then rays
/// aimed from outside at vertices and edge midpoints, one box diagonal away, target at `t = 1`.
pub struct CheckRays {
    /// All rays, the aimed ones last.
    pub rays: Vec<Ray>,
    /// Index of the first aimed ray.
    pub aimed_from: usize,
    /// Per aimed ray, whether it crosses the surface transversally at its target: the faces around
    /// the target (welded by position) all face it the same way, none within ~3° of edge-on.
    /// Only those can leak; the others may graze a silhouette.
    pub transversal: Vec<bool>,
}

impl CheckRays {
    /// `mixed` rays of `workload` (evenly spaced) and `aimed` rays at `mesh`'s vertices and edges.
    pub fn new(mesh: &TriMesh, workload: &[Ray], mixed: usize, aimed: usize, seed: u64) -> Self {
        let step = (workload.len() / mixed.max(1)).max(1);
        let mut rays: Vec<Ray> = workload.iter().step_by(step).take(mixed).copied().collect();
        let aimed_from = rays.len();
        let b = mesh.bounds();
        let (center, diag) = (0.5 * (b.min + b.max), b.extent().length());
        let mut rng = SplitMix64::new(seed);
        let tris = mesh.triangles();
        let stars = Stars::new(mesh);
        let mut transversal = Vec::new();
        for k in 0..if tris.is_empty() { 0 } else { aimed } {
            let prim = rng.below(tris.len());
            let tri = tris[prim];
            let v = rng.below(3);
            let (target, star) = if k % 2 == 0 {
                (tri[v], stars.around(&[tri[v]]))
            } else {
                let w = tri[(v + 1) % 3];
                (0.5 * (tri[v] + w), stars.around(&[tri[v], w]))
            };
            // From the target's side of the scene, so most rays meet the surface there.
            let mut out = rng.unit_vector();
            if out.dot(target - center) < 0.0 {
                out = -out;
            }
            let org = target + out * diag;
            let ray = Ray::new(org, target - org);
            let d = ray.dir.normalize();
            let facing: Vec<f32> = star.iter().map(|n| d.dot(*n)).collect();
            transversal.push(
                !facing.is_empty()
                    && (facing.iter().all(|&c| c > 0.05) || facing.iter().all(|&c| c < -0.05)),
            );
            rays.push(ray);
        }
        CheckRays {
            rays,
            aimed_from,
            transversal,
        }
    }
}

/// Unit normals of the faces around vertices, with vertices welded by exact position.
struct Stars {
    faces_of: HashMap<[u32; 3], Vec<usize>>,
    normals: Vec<Vec3>,
}

impl Stars {
    fn new(mesh: &TriMesh) -> Stars {
        let mut faces_of: HashMap<[u32; 3], Vec<usize>> = HashMap::new();
        let normals = mesh
            .triangles()
            .iter()
            .enumerate()
            .map(|(i, t)| {
                for p in t {
                    faces_of
                        .entry(p.to_array().map(f32::to_bits))
                        .or_default()
                        .push(i);
                }
                (t[1] - t[0]).cross(t[2] - t[0]).normalize_or_zero()
            })
            .collect();
        Stars { faces_of, normals }
    }

    /// The normals of the faces that hold every one of `points` (a vertex, or an edge's ends).
    fn around(&self, points: &[Vec3]) -> Vec<Vec3> {
        let key = |p: &Vec3| p.to_array().map(f32::to_bits);
        let Some(first) = self.faces_of.get(&key(&points[0])) else {
            return Vec::new();
        };
        first
            .iter()
            .filter(|f| {
                points[1..]
                    .iter()
                    .all(|p| self.faces_of.get(&key(p)).is_some_and(|l| l.contains(f)))
            })
            .map(|&f| self.normals[f])
            .filter(|n| *n != Vec3::ZERO)
            .collect()
    }
}

/// The exact answers for `rays`.
pub fn reference(mesh: &TriMesh, rays: &[Ray]) -> Vec<Hit> {
    let brute = BruteForce::new(mesh);
    rays.iter().map(|r| brute.intersect(mesh, r)).collect()
}

/// True when `mesh` is closed: with vertices welded by exact position, every directed edge of a
/// non-degenerate triangle has its reverse.
pub fn is_closed(mesh: &TriMesh) -> bool {
    let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
    let mut id = |p: Vec3| {
        let key = p.to_array().map(f32::to_bits);
        let next = ids.len() as u32;
        *ids.entry(key).or_insert(next)
    };
    let mut edges = HashSet::new();
    for (i, tri) in mesh.triangles().iter().enumerate() {
        if mesh.is_degenerate(i as u32) {
            continue;
        }
        let v = tri.map(&mut id);
        if v[0] == v[1] || v[1] == v[2] || v[0] == v[2] {
            continue;
        }
        for k in 0..3 {
            edges.insert((v[k], v[(k + 1) % 3]));
        }
    }
    !edges.is_empty() && edges.iter().all(|&(a, b)| edges.contains(&(b, a)))
}

/// How one structure or peer did on the check rays.
#[derive(Clone, Copy, Debug)]
pub struct Accuracy {
    /// Share of all check rays answered wrongly.
    pub wrong: f64,
    /// Share of the workload's rays (camera and bounces, not the aimed ones) answered wrongly.
    pub wrong_workload: f64,
    /// Share of the transversal aimed rays that leaked (`None`: the mesh is not closed).
    pub leaks: Option<f64>,
}

/// The exact `t` of `ray` through triangle `prim`, if the exact test hits it.
fn exact_t(mesh: &TriMesh, ray: &Ray, prim: u32) -> Option<f32> {
    let tri = mesh.triangle(prim)?;
    PreparedRay::new(ray)?
        .intersect_triangle(tri[0], tri[1], tri[2])
        .map(|h| h.0)
}

/// Judges `answers` (one per check ray: the triangle named, `Hit::INVALID_ID` for a miss, and the
/// `t` the structure reports) against the exact answers.
pub fn judge(
    mesh: &TriMesh,
    check: &CheckRays,
    want: &[Hit],
    answers: &[(u32, f32)],
    closed: bool,
) -> Accuracy {
    let (mut wrong, mut wrong_mixed, mut leaks) = (0usize, 0usize, 0usize);
    for (k, ((ray, want), &(prim, t))) in check.rays.iter().zip(want).zip(answers).enumerate() {
        let got_t = (prim != Hit::INVALID_ID)
            .then(|| exact_t(mesh, ray, prim))
            .flatten();
        let right = match (want.is_hit(), prim != Hit::INVALID_ID) {
            (false, false) => true,
            (true, true) => got_t == Some(want.t),
            _ => false,
        };
        wrong += usize::from(!right);
        wrong_mixed += usize::from(!right && k < check.aimed_from);
        // A leak by the structure's own account: a transversal ray it reports as a miss or as a hit
        // beyond the surface at the target.
        let crossing = k
            .checked_sub(check.aimed_from)
            .is_some_and(|a| check.transversal[a]);
        if closed && crossing && want.is_hit() && want.t <= 1.0 + 1e-4 {
            leaks += usize::from(prim == Hit::INVALID_ID || t.is_nan() || t > 1.0 + 1e-4);
        }
    }
    let aimed = check.transversal.iter().filter(|&&t| t).count();
    Accuracy {
        wrong: wrong as f64 / check.rays.len().max(1) as f64,
        wrong_workload: wrong_mixed as f64 / check.aimed_from.max(1) as f64,
        leaks: closed.then(|| leaks as f64 / aimed.max(1) as f64),
    }
}
