//! Random and adversarial rays and triangles for the tests of the triangle test and of the structures'
//! list test: triangles of awkward kinds (degenerate, slivers, axis-aligned, tiny) at scales from
//! near-subnormal to huge, rays aimed at vertices, edges and just outside them, lines exactly
//! through a target, grazing and awkward directions.

use glam::Vec3;

use crate::ray::Ray;
use crate::workload::SplitMix64;

pub(crate) fn signed(rng: &mut SplitMix64) -> f32 {
    2.0 * rng.next_f32() - 1.0
}

pub(crate) fn point(rng: &mut SplitMix64) -> Vec3 {
    Vec3::new(signed(rng), signed(rng), signed(rng))
}

/// A log-uniform-ish magnitude in `[10^lo, 10^hi]`.
pub(crate) fn log_uniform(rng: &mut SplitMix64, lo: f32, hi: f32) -> f32 {
    let e = (lo + (hi - lo) * rng.next_f32()) * core::f32::consts::LOG2_10;
    let k = crate::math::floor(e);
    let pow2 = f32::from_bits((((k as i32).clamp(-126, 127) + 127) as u32) << 23);
    pow2 * (1.0 + (e - k))
}

/// A triangle of one of several awkward kinds, before scaling.
pub(crate) fn triangle(rng: &mut SplitMix64) -> [Vec3; 3] {
    let p0 = point(rng);
    match rng.below(8) {
        // Degenerate: collinear or repeated vertices.
        0 => {
            let p1 = point(rng);
            let k = [0.0, 0.5, 2.0, -1.0][rng.below(4)];
            [p0, p1, p0 + k * (p1 - p0)]
        }
        // Sliver: third vertex a tiny distance off the first edge.
        1 => {
            let p1 = point(rng);
            let off = point(rng) * log_uniform(rng, -7.0, -2.0);
            [p0, p1, 0.5 * (p0 + p1) + off]
        }
        // Axis-aligned (a shared coordinate).
        2 => {
            let (mut p1, mut p2) = (point(rng), point(rng));
            let a = rng.below(3);
            p1[a] = p0[a];
            p2[a] = p0[a];
            [p0, p1, p2]
        }
        // Small triangle.
        3 => {
            let s = log_uniform(rng, -4.0, -1.0);
            [p0, p0 + s * point(rng), p0 + s * point(rng)]
        }
        _ => [p0, point(rng), point(rng)],
    }
}

/// A point of the triangle's plane at a vertex, on or near an edge, or inside, sometimes pushed
/// just outside.
pub(crate) fn target(rng: &mut SplitMix64, tri: &[Vec3; 3]) -> Vec3 {
    let mut b = [rng.next_f32(), rng.next_f32(), rng.next_f32()];
    match rng.below(6) {
        0 => {
            b = [0.0; 3];
            b[rng.below(3)] = 1.0;
        }
        1 | 2 => b[rng.below(3)] = 0.0,
        _ => {}
    }
    let sum = b[0] + b[1] + b[2];
    b = if sum > 0.0 {
        b.map(|x| x / sum)
    } else {
        [1.0, 0.0, 0.0]
    };
    if rng.below(2) == 0 {
        let k = rng.below(3);
        let d = log_uniform(rng, -9.0, -2.0);
        b[k] -= d;
        b[(k + 1) % 3] += d;
    }
    match rng.below(8) {
        // An exact vertex, or an exactly representable edge midpoint.
        0 => tri[rng.below(3)],
        1 => {
            let k = rng.below(3);
            0.5 * (tri[k] + tri[(k + 1) % 3])
        }
        _ => b[0] * tri[0] + b[1] * tri[1] + b[2] * tri[2],
    }
}

/// Directions with the awkward cases of the axis choice: ties between components, axis-parallel
/// directions and −0.0 components.
pub(crate) fn awkward_direction(rng: &mut SplitMix64, d: Vec3) -> Vec3 {
    match rng.below(10) {
        0 => {
            let mut e = Vec3::splat(if rng.below(2) == 0 { 0.0 } else { -0.0 });
            e[rng.below(3)] = if rng.below(2) == 0 { 1.0 } else { -1.0 };
            e
        }
        1 => {
            let mut e = d;
            let (i, j) = (rng.below(3), rng.below(3));
            e[i] = e[j].abs() * if rng.below(2) == 0 { 1.0 } else { -1.0 };
            e
        }
        2 => Vec3::new(1.0, -1.0, if rng.below(2) == 0 { 1.0 } else { -1.0 }),
        _ => d,
    }
}

/// Scales and offsets of the scenes the pairs are placed in: unit, tiny, near-subnormal, huge, far
/// from the origin.
pub(crate) const SCALES: [(f32, Vec3); 8] = [
    (1.0, Vec3::ZERO),
    (1e-20, Vec3::ZERO),
    (1e-38, Vec3::ZERO),
    (1e30, Vec3::ZERO),
    (1e-2, Vec3::new(1e4, -2e4, 3e4)),
    (1.0, Vec3::new(3e6, 0.0, -1e6)),
    (1e5, Vec3::new(-1e3, 1e3, 0.5)),
    (1.0, Vec3::new(0.25, 0.5, -0.75)),
];

/// Pair number `case`: a triangle and a ray aimed at it (a vertex, an edge, inside, just outside),
/// from near or far, sometimes grazing, sometimes in an awkward direction; one in eight is a plain
/// random ray.
pub(crate) fn pair(rng: &mut SplitMix64, case: usize) -> (Ray, [Vec3; 3]) {
    let (scale, offset) = SCALES[case % SCALES.len()];
    let tri = triangle(rng).map(|p| p * scale + offset);
    if case % 8 == 7 {
        let ray = Ray::new(point(rng) * 2.0 * scale + offset, point(rng));
        return (ray, tri);
    }
    let aim = target(rng, &tri);
    if case % 8 == 3 {
        // A line exactly through the target (often a vertex or an edge midpoint): the origin a
        // small integer vector away, so `aim − org` is exact and the exact edge functions of the
        // edges through the target are zero, where floating point gives noise of either sign.
        let v = Vec3::new(
            rng.below(7) as f32 - 3.0,
            rng.below(7) as f32 - 3.0,
            rng.below(5) as f32 + 1.0,
        ) * (scale * 0.25);
        let org = aim + v;
        return (Ray::new(org, aim - org), tri);
    }
    let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
    let mut out = point(rng).normalize_or(Vec3::X);
    if rng.below(5) == 0 && n.length() > 0.0 && n.is_finite() {
        let n = n.normalize();
        out = (out - n * out.dot(n)).normalize_or(Vec3::X) + n * log_uniform(rng, -7.0, -1.0);
    }
    let org = aim + out * (scale * log_uniform(rng, -3.0, 3.0));
    let dir = match rng.below(8) {
        0 => point(rng),
        1 => awkward_direction(rng, aim - org),
        _ => (aim - org) * log_uniform(rng, -3.0, 3.0),
    };
    (Ray::new(org, dir), tri)
}
