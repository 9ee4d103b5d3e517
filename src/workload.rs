//! Ray workloads: camera rays, diffuse bounces, and adversarial rays, shared by tests, benches,
//! examples and (later) the selector's sample rays. Deterministic for a given seed.

use alloc::vec::Vec;
use glam::Vec3;

use crate::math;
use crate::mesh::TriMesh;
use crate::ray::Aabb;
use crate::ray::{Hit, Ray};

/// A small, fast, deterministic PRNG (SplitMix64). Not for cryptography.
#[derive(Clone, Debug)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator seeded with `seed`; the same seed gives the same sequence everywhere.
    pub fn new(seed: u64) -> Self {
        SplitMix64(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix64(self.0)
    }

    /// A point uniform in the unit cube `[0, 1)³`.
    pub fn next_vec3(&mut self) -> Vec3 {
        let x = self.next_f32();
        let y = self.next_f32();
        let z = self.next_f32();
        Vec3::new(x, y, z)
    }

    /// A float uniform in `[0, 1)`.
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 * (1.0 / (1u64 << 24) as f32)
    }

    /// An integer uniform in `[0, n)` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (((self.next_u64() >> 32) * n as u64) >> 32) as usize
    }

    /// A direction uniform on the unit sphere.
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = 2.0 * self.next_f32() - 1.0;
        let phi = core::f32::consts::TAU * self.next_f32();
        let s = math::sqrt((1.0 - z * z).max(0.0));
        Vec3::new(s * math::cos(phi), s * math::sin(phi), z)
    }
}

/// The SplitMix64 finaliser: a bijective 64-bit hash, also used to derive values from positions.
pub fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A pinhole camera looking at the centre of a box from a diagonal, one box diagonal away, with a
/// 45° field of view: the view every workload, test and the selector's sample rays use.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    eye: Vec3,
    forward: Vec3,
    right: Vec3,
    up: Vec3,
    side: usize,
}

impl Camera {
    /// The camera for `bounds` with an image of `side × side` pixels.
    pub fn looking_at(bounds: &Aabb, side: usize) -> Camera {
        let center = 0.5 * (bounds.min + bounds.max);
        let diag = bounds.extent().length().max(f32::MIN_POSITIVE);
        let eye = center + Vec3::new(0.62, -0.55, 0.45) * diag;
        let forward = (center - eye).normalize_or(Vec3::X);
        let up = if forward.z.abs() > 0.9 {
            Vec3::Y
        } else {
            Vec3::Z
        };
        let right = forward.cross(up).normalize_or(Vec3::Y);
        let up = right.cross(forward);
        Camera {
            eye,
            forward,
            right,
            up,
            side: side.max(1),
        }
    }

    /// The ray through pixel `(i, j)`, jittered inside the pixel by `rng`.
    pub fn ray(&self, i: usize, j: usize, rng: &mut SplitMix64) -> Ray {
        let half = 0.414_213_57; // tan(22.5°)
        let side = self.side as f32;
        let x = (2.0 * (i as f32 + rng.next_f32()) / side - 1.0) * half;
        let y = (1.0 - 2.0 * (j as f32 + rng.next_f32()) / side) * half;
        Ray::new(self.eye, self.forward + x * self.right + y * self.up)
    }
}

/// Pinhole camera rays (`side × side`, one jittered sample per pixel) of [`Camera::looking_at`].
pub fn camera_rays(bounds: &Aabb, side: usize, rng: &mut SplitMix64) -> Vec<Ray> {
    let camera = Camera::looking_at(bounds, side);
    let mut rays = Vec::with_capacity(side * side);
    for j in 0..side {
        for i in 0..side {
            rays.push(camera.ray(i, j, rng));
        }
    }
    rays
}

/// The offset a bounce starts at so that it does not hit its own triangle: 1e-5 of the scene's
/// diagonal.
pub fn bounce_offset(mesh: &TriMesh) -> f32 {
    1e-5 * mesh.bounds().extent().length()
}

/// A diffuse bounce from `hit` of `ray`: the origin is the hit point, the direction
/// cosine-distributed about the geometric normal facing the incoming ray, and `tmin = offset`
/// (see [`bounce_offset`]). `None` when `hit` is a miss.
pub fn bounce(
    mesh: &TriMesh,
    ray: &Ray,
    hit: &Hit,
    offset: f32,
    rng: &mut SplitMix64,
) -> Option<Ray> {
    let tri = mesh.triangle(hit.prim)?;
    let mut n = (tri[1] - tri[0]).cross(tri[2] - tri[0]).normalize_or_zero();
    if n.dot(ray.dir) > 0.0 {
        n = -n;
    }
    let mut d = rng.unit_vector();
    if d.dot(n) < 0.0 {
        d = -d;
    }
    Some(Ray::segment(
        ray.org + hit.t * ray.dir,
        d + n,
        offset,
        f32::INFINITY,
    ))
}

/// One diffuse bounce (see [`bounce`]) from every hit of `primary`.
pub fn bounce_rays(
    mesh: &TriMesh,
    primary: &[Ray],
    hits: &[Hit],
    rng: &mut SplitMix64,
) -> Vec<Ray> {
    let offset = bounce_offset(mesh);
    let mut out = Vec::with_capacity(primary.len());
    for (ray, hit) in primary.iter().zip(hits) {
        out.extend(bounce(mesh, ray, hit, offset, rng));
    }
    out
}

/// Rays that break tracers, in `bounds` (the mesh's vertices give the aimed ones): random origins and
/// directions, axis-parallel and −0.0 directions, origins on the grid's likely cell boundaries, rays
/// aimed exactly at vertices and edge midpoints from outside, finite segments, and `tmin == tmax`.
pub fn adversarial_rays(mesh: &TriMesh, count: usize, rng: &mut SplitMix64) -> Vec<Ray> {
    let b = mesh.bounds();
    let (lo, ext) = (b.min, b.extent());
    let diag = ext.length().max(1e-30);
    let random_point =
        |rng: &mut SplitMix64| lo + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * ext;
    let mut rays = Vec::with_capacity(count);
    for k in 0..count {
        let ray = match k % 8 {
            0 => Ray::new(random_point(rng), rng.unit_vector()),
            1 => {
                let mut d = Vec3::ZERO;
                d[rng.below(3)] = if rng.next_f32() < 0.5 { -1.0 } else { 1.0 };
                Ray::new(random_point(rng), d)
            }
            2 => {
                // −0.0 components next to a non-zero one.
                let mut d = Vec3::splat(-0.0);
                d[rng.below(3)] = if rng.next_f32() < 0.5 { -1.0 } else { 1.0 };
                let a = rng.below(3);
                if d[a] == 0.0 {
                    d[a] = 0.25;
                }
                Ray::new(random_point(rng), d)
            }
            3 | 4 if !mesh.is_empty() => {
                let tri = mesh.triangles()[rng.below(mesh.len())];
                let v = rng.below(3);
                let target = if k % 8 == 3 {
                    tri[v]
                } else {
                    0.5 * (tri[v] + tri[(v + 1) % 3])
                };
                let org = target + rng.unit_vector() * diag;
                Ray::new(org, target - org)
            }
            5 => {
                // Origins on planes at simple fractions of the box, where cell boundaries tend to lie.
                let mut o = random_point(rng);
                let a = rng.below(3);
                o[a] = lo[a] + ext[a] * (rng.below(9) as f32 / 8.0);
                Ray::new(o, rng.unit_vector())
            }
            6 => {
                let (p, q) = (random_point(rng), random_point(rng));
                Ray::segment(p, q - p, 0.0, 1.0)
            }
            _ => {
                let o = random_point(rng);
                let d = rng.unit_vector();
                let t = rng.next_f32() * diag;
                Ray::segment(o, d, t, t)
            }
        };
        rays.push(ray);
    }
    rays
}
