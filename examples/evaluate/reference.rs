//! An f64 reference for hit accuracy: Möller–Trumbore in f64 over every triangle, no tolerance, so
//! it says what the exact answer for the f32 ray and mesh is (up to f64 rounding).

use rayq::{Ray, TriMesh};

/// The reference's answer: the nearest `t` and its triangle, or `None` for a miss.
pub type Answer = Option<(f64, u32)>;

/// `t` of the ray through triangle `prim` in f64, or `None` when it misses or lies outside the
/// ray's window.
pub fn t_of(mesh: &TriMesh, ray: &Ray, prim: u32) -> Option<f64> {
    let tri = mesh.triangle(prim)?;
    let (o, d) = (ray.org.as_dvec3(), ray.dir.as_dvec3());
    let (a, b, c) = (tri[0].as_dvec3(), tri[1].as_dvec3(), tri[2].as_dvec3());
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    let inside = u >= 0.0 && v >= 0.0 && u + v <= 1.0;
    (inside && t >= f64::from(ray.tmin) && t <= f64::from(ray.tmax)).then_some(t)
}

/// The closest hit's `t` and triangle over the whole mesh (`None`: a miss).
pub fn closest(mesh: &TriMesh, ray: &Ray) -> Answer {
    let mut best: Option<(f64, u32)> = None;
    for prim in 0..mesh.len() as u32 {
        if let Some(t) = t_of(mesh, ray, prim) {
            if best.map_or(true, |(bt, _)| t < bt) {
                best = Some((t, prim));
            }
        }
    }
    best
}

/// True when `prim` (or a miss, `u32::MAX`) is an exact answer for the ray: the reference's
/// verdict on hit or miss, and for a hit a triangle the ray meets at the reference's nearest `t`
/// (within 1e-6 relative: ties at shared edges and vertices are all right).
pub fn agrees(mesh: &TriMesh, ray: &Ray, want: Answer, prim: u32) -> bool {
    match want {
        None => prim == u32::MAX,
        Some((t, _)) => {
            prim != u32::MAX
                && t_of(mesh, ray, prim)
                    .is_some_and(|pt| (pt - t).abs() <= 1e-6 * t.abs().max(1e-30))
        }
    }
}
