//! Procedural scenes in the spirit of Eric Haines' Standard Procedural Databases (SPD).
//!
//! Every generator returns a [`MeshData`] whose coordinates are finite and whose indices are in
//! range, and is deterministic: the same arguments give the same mesh, bit for bit, on a given build.
//! [`by_name`] picks a generator's parameters so that a scene has roughly a requested triangle count,
//! from ~10^3 to 10^6 triangles and beyond.
//!
//! Generators allocate their whole output and panic only when it cannot fit in memory or when a mesh
//! would need more than `u32::MAX` vertices.

use alloc::vec::Vec;
use core::f32::consts::{PI, TAU};
use glam::Vec3;

use crate::math;
use crate::mesh::MeshData;
use crate::workload::{mix64, SplitMix64};

/// The scene names [`by_name`] understands.
pub const NAMES: &[&str] = &[
    "sphereflake",
    "tetra",
    "mount",
    "rings",
    "gears",
    "stadium",
    "sphere",
    "soup",
    "slivers",
    "hair",
];

impl MeshData {
    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.vertices.len()
    }

    /// The three corners of triangle `i` (panics if `i >= triangle_count()` or an index is out of range).
    pub fn triangle(&self, i: usize) -> [[f32; 3]; 3] {
        self.indices[i].map(|v| self.vertices[v as usize])
    }

    /// Appends `other`'s vertices and triangles; `other`'s triangles keep their order and come after ours.
    pub fn append(&mut self, other: &MeshData) {
        let base = self.next_index();
        self.vertices.extend_from_slice(&other.vertices);
        self.indices
            .extend(other.indices.iter().map(|t| t.map(|i| i + base)));
    }

    /// A copy with every vertex mapped to `v * scale + offset`; triangles are unchanged.
    pub fn transformed(&self, scale: f32, offset: [f32; 3]) -> MeshData {
        let o = Vec3::from(offset);
        MeshData {
            vertices: self
                .vertices
                .iter()
                .map(|&v| (Vec3::from(v) * scale + o).to_array())
                .collect(),
            indices: self.indices.clone(),
        }
    }

    fn with_capacity(vertices: usize, triangles: usize) -> Self {
        MeshData {
            vertices: Vec::with_capacity(vertices),
            indices: Vec::with_capacity(triangles),
        }
    }

    /// The index the next pushed vertex will get.
    fn next_index(&self) -> u32 {
        u32::try_from(self.vertices.len()).expect("generated mesh has more than u32::MAX vertices")
    }

    fn push_vertex(&mut self, v: Vec3) -> u32 {
        let i = self.next_index();
        self.vertices.push(v.to_array());
        i
    }

    /// Appends `template` scaled by `scale` and moved to `centre`.
    fn push_instance(&mut self, template: &MeshData, centre: Vec3, scale: f32) {
        let base = self.next_index();
        self.vertices.extend(
            template
                .vertices
                .iter()
                .map(|&v| (Vec3::from(v) * scale + centre).to_array()),
        );
        self.indices
            .extend(template.indices.iter().map(|t| t.map(|i| i + base)));
    }
}

/// Two unit vectors that complete `n` (unit length) to a right-handed orthonormal basis
/// (Duff et al. 2017).
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let s = if n.z >= 0.0 { 1.0 } else { -1.0 };
    let a = -1.0 / (s + n.z);
    let b = n.x * n.y * a;
    (
        Vec3::new(1.0 + s * n.x * n.x * a, s * b, -s * n.x),
        Vec3::new(b, s + n.y * n.y * a, -n.y),
    )
}

/// `(cos, sin)` of `k * TAU / n` for `k` in `0..n`.
fn circle(n: u32) -> Vec<(f32, f32)> {
    (0..n)
        .map(|k| {
            let a = k as f32 * (TAU / n as f32);
            (math::cos(a), math::sin(a))
        })
        .collect()
}

/// Triangle count of [`closed_sphere`]`(n)` for `n >= 2`.
fn sphere_tris(n: u32) -> usize {
    4 * n as usize * (n as usize - 1)
}

/// The parameter in `lo..=hi` whose count `f(p)` (non-decreasing in `p`) is closest to `target` in
/// ratio.
fn closest(lo: u32, hi: u32, target: usize, f: impl Fn(u32) -> usize) -> u32 {
    let target = target.max(1) as f64;
    let err = |n: usize| {
        let n = n.max(1) as f64;
        if n > target {
            n / target
        } else {
            target / n
        }
    };
    let mut best = lo;
    for p in lo..=hi {
        let n = f(p);
        if err(n) < err(f(best)) {
            best = p;
        }
        if n as f64 >= target {
            break;
        }
    }
    best
}

/// A closed, watertight unit sphere at the origin: latitude/longitude tessellation with `n` bands
/// (`subdiv`, clamped to at least 2) and `2n` segments, single pole vertices, every vertex shared.
///
/// Every undirected edge belongs to exactly two triangles that traverse it in opposite directions, and
/// every triangle winds counter-clockwise seen from outside. Triangles: `4n(n - 1)`; vertices:
/// `2n(n - 1) + 2`.
pub fn closed_sphere(subdiv: u32) -> MeshData {
    let n = subdiv.max(2);
    let m = 2 * n;
    let ring_count = (n - 1) as usize * m as usize;
    let mut mesh = MeshData::with_capacity(ring_count + 2, sphere_tris(n));
    let around = circle(m);
    let north = mesh.push_vertex(Vec3::Z);
    for k in 1..n {
        let theta = k as f32 * (PI / n as f32);
        let (z, rho) = (math::cos(theta), math::sin(theta));
        for &(c, s) in &around {
            mesh.push_vertex(Vec3::new(rho * c, rho * s, z));
        }
    }
    let south = mesh.push_vertex(-Vec3::Z);
    // Vertex of ring `k` (1..n) at segment `s` (wrapping).
    let at = |k: u32, s: u32| 1 + (k - 1) * m + s % m;
    for s in 0..m {
        mesh.indices.push([north, at(1, s), at(1, s + 1)]);
        for k in 1..n - 1 {
            let (a, b) = (at(k, s), at(k, s + 1));
            let (c, d) = (at(k + 1, s), at(k + 1, s + 1));
            mesh.indices.push([a, c, d]);
            mesh.indices.push([a, d, b]);
        }
        mesh.indices.push([south, at(n - 1, s + 1), at(n - 1, s)]);
    }
    mesh
}

/// A recursive sphere flake: a unit sphere at the origin carrying 9 children of 1/3 its radius
/// touching it (6 around its equator, 3 above), each carrying 9 children in turn, `levels` times.
///
/// Every sphere is a [`closed_sphere`]`(sphere_subdiv)`. Spheres: `(9^(levels+1) - 1) / 8`;
/// triangles: that times `4n(n - 1)` with `n = max(sphere_subdiv, 2)`, i.e. ×9 per level.
pub fn sphereflake(levels: u32, sphere_subdiv: u32) -> MeshData {
    let template = closed_sphere(sphere_subdiv);
    let spheres = (0..=levels).fold(0usize, |acc, _| acc * 9 + 1);
    let mut mesh = MeshData::with_capacity(
        spheres * template.vertex_count(),
        spheres * template.triangle_count(),
    );
    // Child directions in a (u, v, up) frame: 6 on the equator, 3 at 60 degrees elevation.
    let (ce, se) = (0.5, 0.866_025_4);
    let children: Vec<Vec3> = circle(6)
        .into_iter()
        .map(|(c, s)| Vec3::new(c, s, 0.0))
        .chain(circle(3).into_iter().map(|(c, s)| {
            // Rotated by 30 degrees so they sit between the equatorial ones.
            let (c30, s30) = (se, ce);
            Vec3::new(ce * (c * c30 - s * s30), ce * (s * c30 + c * s30), se)
        }))
        .collect();
    flake(
        &mut mesh,
        &template,
        &children,
        Vec3::ZERO,
        1.0,
        Vec3::Z,
        levels,
    );
    mesh
}

fn flake(
    mesh: &mut MeshData,
    template: &MeshData,
    children: &[Vec3],
    centre: Vec3,
    radius: f32,
    up: Vec3,
    levels: u32,
) {
    mesh.push_instance(template, centre, radius);
    if levels == 0 {
        return;
    }
    let (u, v) = basis(up);
    let r = radius / 3.0;
    for d in children {
        let dir = (u * d.x + v * d.y + up * d.z).normalize();
        flake(
            mesh,
            template,
            children,
            centre + dir * (radius + r),
            r,
            dir,
            levels - 1,
        );
    }
}

/// A Sierpinski tetrahedron: a regular tetrahedron (corners `(±1, ±1, ±1)` with an even number of
/// minus signs) recursively replaced by 4 half-size copies at its corners, `depth` times.
///
/// Tetrahedra: `4^depth`, each closed with 4 outward-facing triangles of its own 4 vertices;
/// triangles: `4^(depth+1)`. The solid fills `2^-depth` of the outer tetrahedron.
pub fn tetra(depth: u32) -> MeshData {
    let count = 1usize << (2 * depth);
    let mut mesh = MeshData::with_capacity(4 * count, 4 * count);
    let corners = [
        Vec3::new(1.0, 1.0, 1.0),
        Vec3::new(1.0, -1.0, -1.0),
        Vec3::new(-1.0, 1.0, -1.0),
        Vec3::new(-1.0, -1.0, 1.0),
    ];
    sierpinski(&mut mesh, corners, depth);
    mesh
}

fn sierpinski(mesh: &mut MeshData, c: [Vec3; 4], depth: u32) {
    if depth == 0 {
        let base = mesh.next_index();
        for v in c {
            mesh.push_vertex(v);
        }
        for (i, j, k, l) in [(0, 1, 2, 3), (0, 1, 3, 2), (0, 2, 3, 1), (1, 2, 3, 0)] {
            let n = (c[j] - c[i]).cross(c[k] - c[i]);
            let (j, k) = if n.dot(c[l] - c[i]) > 0.0 {
                (k, j)
            } else {
                (j, k)
            };
            mesh.indices.push([i, j, k].map(|x| base + x as u32));
        }
        return;
    }
    for i in 0..4 {
        sierpinski(mesh, c.map(|v| (c[i] + v) * 0.5), depth - 1);
    }
}

/// A fractal mountain: an equilateral triangle of side 1 in the plane z = 0 (corners `(0, 0)`,
/// `(1, 0)`, `(0.5, √3/2)`) subdivided `depth` times by midpoint displacement, the height of each new
/// vertex being the mean of its edge's ends plus a random offset proportional to the edge length.
///
/// An open height field with shared vertices and upward-facing triangles; the heights are a pure
/// function of `(seed, lattice position)`. Triangles: `4^depth`; vertices: `(2^d + 1)(2^d + 2) / 2`.
pub fn mount(depth: u32, seed: u64) -> MeshData {
    let n = 1usize << depth;
    let idx = |i: usize, j: usize| j * (2 * n + 3 - j) / 2 + i;
    let mut h = alloc::vec![0.0f32; idx(0, n) + 1];
    let seed = mix64(seed);
    let noise = |i: usize, j: usize| {
        let r = mix64(seed ^ mix64(((i as u64) << 32) | j as u64));
        (r >> 40) as f32 * (2.0 / (1u32 << 24) as f32) - 1.0
    };
    let mut step = n;
    while step > 1 {
        let half = step / 2;
        let amp = 0.35 * step as f32 / n as f32;
        for j in (0..=n).step_by(half) {
            for i in (0..=n - j).step_by(half) {
                let (a, b) = match ((i / half) % 2, (j / half) % 2) {
                    (0, 0) => continue,
                    (1, 0) => ((i - half, j), (i + half, j)),
                    (0, _) => ((i, j - half), (i, j + half)),
                    _ => ((i - half, j + half), (i + half, j - half)),
                };
                h[idx(i, j)] = 0.5 * (h[idx(a.0, a.1)] + h[idx(b.0, b.1)]) + amp * noise(i, j);
            }
        }
        step = half;
    }
    let mut mesh = MeshData::with_capacity(h.len(), n * n);
    let inv = 1.0 / n as f32;
    for j in 0..=n {
        for i in 0..=n - j {
            let (x, y) = (
                (i as f32 + 0.5 * j as f32) * inv,
                j as f32 * inv * 0.866_025_4,
            );
            mesh.push_vertex(Vec3::new(x, y, h[idx(i, j)]));
        }
    }
    let id = |i: usize, j: usize| idx(i, j) as u32;
    for j in 0..n {
        for i in 0..n - j {
            mesh.indices.push([id(i, j), id(i + 1, j), id(i, j + 1)]);
            if i + j + 1 < n {
                mesh.indices
                    .push([id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
    }
    mesh
}

/// Triangles of one torus in [`rings`].
fn torus_tris(segments: u32) -> usize {
    let (major, minor) = torus_segments(segments);
    2 * major as usize * minor as usize
}

fn torus_segments(segments: u32) -> (u32, u32) {
    let major = segments.max(3);
    (major, (major / 2).max(3))
}

/// `count` closed tori (major radius 1, tube radius 0.2) on a cubic lattice of spacing 2.4, filled
/// x first, then y, then z; each torus's axis is x, y or z in turn, so neighbours are crossed.
///
/// Each torus has `s = max(segments, 3)` segments around the ring and `max(s / 2, 3)` around the
/// tube, shared vertices and outward winding. Triangles: `count * 2 * s * max(s / 2, 3)` (≈ `count * s²`).
pub fn rings(count: u32, segments: u32) -> MeshData {
    let (major, minor) = torus_segments(segments);
    let per = major as usize * minor as usize;
    let mut mesh = MeshData::with_capacity(count as usize * per, count as usize * 2 * per);
    let (big, small) = (circle(major), circle(minor));
    let side = (1..)
        .find(|g: &u32| (*g as u64).pow(3) >= count as u64)
        .unwrap_or(1);
    let axes = [Vec3::X, Vec3::Y, Vec3::Z];
    for k in 0..count {
        let cell = [k % side, (k / side) % side, k / (side * side)];
        let centre = Vec3::from(cell.map(|c| c as f32 * 2.4));
        let axis = axes[(cell.iter().sum::<u32>() % 3) as usize];
        let (u, v) = basis(axis);
        let base = mesh.next_index();
        for &(cp, sp) in &big {
            let radial = u * cp + v * sp;
            for &(ct, st) in &small {
                mesh.push_vertex(centre + radial * (1.0 + 0.2 * ct) + axis * (0.2 * st));
            }
        }
        let at = |a: u32, b: u32| base + (a % major) * minor + b % minor;
        for a in 0..major {
            for b in 0..minor {
                let (p, q) = (at(a, b), at(a + 1, b));
                let (r, s) = (at(a + 1, b + 1), at(a, b + 1));
                mesh.indices.push([p, q, r]);
                mesh.indices.push([p, r, s]);
            }
        }
    }
    mesh
}

/// `count` closed gear prisms (outer radius 1, root radius 0.8, thickness 0.3, axis z) on a square
/// grid of spacing 1.85 in the plane z = 0, every other gear turned by half a tooth so that
/// neighbours' teeth interleave.
///
/// Each gear has `t = max(teeth, 3)` teeth, a profile of `4t` points fanned from a centre vertex on
/// both caps, shared vertices and outward winding. Triangles: `count * 16t`.
pub fn gears(count: u32, teeth: u32) -> MeshData {
    let t = teeth.max(3);
    let p = 4 * t;
    let pitch = TAU / t as f32;
    // (angle within a tooth as a fraction of the pitch, radius)
    let profile = [(0.0, 0.8), (0.15, 1.0), (0.45, 1.0), (0.6, 0.8)];
    let side = (1..)
        .find(|g: &u32| (*g as u64).pow(2) >= count as u64)
        .unwrap_or(1);
    let mut mesh = MeshData::with_capacity(
        count as usize * (2 * p as usize + 2),
        count as usize * 4 * p as usize,
    );
    for k in 0..count {
        let (col, row) = (k % side, k / side);
        let centre = Vec3::new(col as f32 * 1.85, row as f32 * 1.85, 0.0);
        let turn = if (col + row) % 2 == 1 { 0.5 } else { 0.0 };
        let base = mesh.next_index();
        for z in [-0.15, 0.15] {
            mesh.push_vertex(centre + Vec3::new(0.0, 0.0, z));
            for tooth in 0..t {
                for (f, r) in profile {
                    let a = (tooth as f32 + f + turn) * pitch;
                    mesh.push_vertex(centre + Vec3::new(r * math::cos(a), r * math::sin(a), z));
                }
            }
        }
        let (cb, ct) = (base, base + p + 1);
        let bot = |i: u32| base + 1 + i % p;
        let top = |i: u32| base + p + 2 + i % p;
        for i in 0..p {
            mesh.indices.push([ct, top(i), top(i + 1)]);
            mesh.indices.push([cb, bot(i + 1), bot(i)]);
            mesh.indices.push([bot(i), bot(i + 1), top(i + 1)]);
            mesh.indices.push([bot(i), top(i + 1), top(i)]);
        }
    }
    mesh
}

/// The "teapot in a stadium": a closed sphere of radius 0.5 resting on the origin (centre
/// `(0, 0, 0.5)`) with about `object_tris` triangles, on a flat 1000 × 600 field in z = 0
/// (x in [-500, 500], y in [-300, 300]) triangulated into about `field_tris` upward-facing triangles
/// (none when `field_tris < 2`).
///
/// The sphere comes first (`4n(n - 1)` triangles with `n >= 2` chosen closest to `object_tris`), then
/// the field (`2 * nx * ny` triangles, `nx / ny ≈ 5 / 3`).
pub fn teapot_in_stadium(object_tris: usize, field_tris: usize) -> MeshData {
    let n = closest(2, u32::MAX, object_tris, sphere_tris);
    let mut mesh = closed_sphere(n).transformed(0.5, [0.0, 0.0, 0.5]);
    let cells = field_tris / 2;
    if cells == 0 {
        return mesh;
    }
    let nx = (math::sqrt64(cells as f64 * 5.0 / 3.0) + 0.5).max(1.0) as usize;
    let ny = ((cells as f64 / nx as f64) + 0.5).max(1.0) as usize;
    let mut field = MeshData::with_capacity((nx + 1) * (ny + 1), 2 * nx * ny);
    for j in 0..=ny {
        for i in 0..=nx {
            let x = -500.0 + 1000.0 * (i as f32 / nx as f32);
            let y = -300.0 + 600.0 * (j as f32 / ny as f32);
            field.push_vertex(Vec3::new(x, y, 0.0));
        }
    }
    let at = |i: usize, j: usize| (j * (nx + 1) + i) as u32;
    for j in 0..ny {
        for i in 0..nx {
            field
                .indices
                .push([at(i, j), at(i + 1, j), at(i + 1, j + 1)]);
            field
                .indices
                .push([at(i, j), at(i + 1, j + 1), at(i, j + 1)]);
        }
    }
    mesh.append(&field);
    mesh
}

/// `n` independent random triangles, uniformly spread: each lies in an axis-aligned cube of side
/// `size` (clamped to [0, 1]) placed uniformly inside the unit cube [0, 1]³, its corners uniform in
/// that cube.
///
/// Triangles: `n`; vertices: `3n` (none shared). Deterministic from `seed`.
pub fn random_soup(n: usize, seed: u64, size: f32) -> MeshData {
    let size = if size > 0.0 { size.min(1.0) } else { 0.0 };
    let mut rng = SplitMix64::new(seed);
    let mut mesh = MeshData::with_capacity(3 * n, n);
    for _ in 0..n {
        let origin = rng.next_vec3() * (1.0 - size);
        let base = mesh.next_index();
        for _ in 0..3 {
            let v = origin + rng.next_vec3() * size;
            mesh.push_vertex(v);
        }
        mesh.indices.push([base, base + 1, base + 2]);
    }
    mesh
}

/// `n` long thin triangles spanning the unit cube: two corners on opposite faces (a random axis, the
/// other coordinates uniform), the third near a random point of the segment between them (jitter
/// below 0.002 per axis, clamped to [0, 1]³).
///
/// All vertices lie in [0, 1]³. Triangles: `n`; vertices: `3n`. Deterministic from `seed`.
pub fn random_slivers(n: usize, seed: u64) -> MeshData {
    let mut rng = SplitMix64::new(seed);
    let mut mesh = MeshData::with_capacity(3 * n, n);
    for _ in 0..n {
        let axis = (rng.next_u64() % 3) as usize;
        let (mut a, mut b) = (rng.next_vec3(), rng.next_vec3());
        a[axis] = 0.0;
        b[axis] = 1.0;
        let t = rng.next_f32();
        let jitter = (rng.next_vec3() - Vec3::splat(0.5)) * 0.004;
        let c = (a.lerp(b, t) + jitter).clamp(Vec3::ZERO, Vec3::ONE);
        let base = mesh.next_index();
        for v in [a, b, c] {
            mesh.push_vertex(v);
        }
        mesh.indices.push([base, base + 1, base + 2]);
    }
    mesh
}

/// `strands` hair-like strands across the unit cube at all angles: each a ribbon of `segments` quads
/// (two triangles each) 0.001 wide, from a root uniform in the cube along a direction uniform on the
/// sphere, 0.3 to 1 long, bending a little at every joint, clamped to [0, 1]³. Long thin triangles
/// (about 100 to 500 times longer than wide) in every orientation: what breaks structures built for
/// well-shaped triangles.
///
/// Triangles: `2·segments·strands`; vertices: `2·(segments + 1)·strands`. Deterministic from `seed`.
pub fn hair(strands: usize, segments: u32, seed: u64) -> MeshData {
    let segments = segments.max(1);
    let mut rng = SplitMix64::new(seed);
    let per = segments as usize;
    let mut mesh = MeshData::with_capacity(2 * (per + 1) * strands, 2 * per * strands);
    let width = 0.001;
    for _ in 0..strands {
        let mut p = rng.next_vec3();
        let mut dir = rng.unit_vector();
        let step = (0.3 + 0.7 * rng.next_f32()) / segments as f32;
        // The ribbon's width lies across the strand.
        let side = dir.any_orthonormal_vector() * (0.5 * width);
        let mut base = mesh.next_index();
        mesh.push_vertex((p - side).clamp(Vec3::ZERO, Vec3::ONE));
        mesh.push_vertex((p + side).clamp(Vec3::ZERO, Vec3::ONE));
        for _ in 0..segments {
            p += dir * step;
            dir = (dir + 0.3 * rng.unit_vector()).normalize_or(dir);
            mesh.push_vertex((p - side).clamp(Vec3::ZERO, Vec3::ONE));
            mesh.push_vertex((p + side).clamp(Vec3::ZERO, Vec3::ONE));
            mesh.indices.push([base, base + 1, base + 2]);
            mesh.indices.push([base + 2, base + 1, base + 3]);
            base += 2;
        }
    }
    mesh
}

/// The scene `name` (one of [`NAMES`]) with parameters chosen so that its triangle count is close to
/// `approx_tris`: within a factor 2 always, and within a few percent for "rings", "gears", "stadium",
/// "soup" and "slivers" once `approx_tris` is in the thousands. `None` for an unknown name.
///
/// Fixed seeds make the result deterministic.
pub fn by_name(name: &str, approx_tris: usize) -> Option<MeshData> {
    let t = approx_tris.max(1);
    let root = math::sqrt64(t as f64);
    Some(match name {
        "sphereflake" => {
            // The deepest flake whose spheres still get 4 bands, then the best sphere resolution.
            let spheres = |levels: u32| (0..=levels).fold(0usize, |acc, _| acc * 9 + 1);
            let levels = (1..=12)
                .take_while(|&l| spheres(l) * sphere_tris(4) <= t)
                .last()
                .unwrap_or(0);
            let n = closest(2, u32::MAX, t, |n| spheres(levels) * sphere_tris(n));
            sphereflake(levels, n)
        }
        "tetra" => tetra(closest(0, 15, t, |d| 1 << (2 * d + 2))),
        "mount" => mount(closest(0, 15, t, |d| 1 << (2 * d)), 0x5eed),
        "rings" => {
            let per_ring = (root / 2.0).max(4.0);
            let segments = (math::sqrt64(t as f64 / per_ring) + 0.5).clamp(6.0, 256.0) as u32;
            let count = (t as f64 / torus_tris(segments) as f64 + 0.5).max(1.0) as u32;
            rings(count, segments)
        }
        "gears" => {
            let teeth = (root / 8.0 + 0.5).clamp(6.0, 256.0) as u32;
            let count = (t as f64 / (16 * teeth) as f64 + 0.5).max(1.0) as u32;
            gears(count, teeth)
        }
        "stadium" => teapot_in_stadium(t * 3 / 4, t - t * 3 / 4),
        "sphere" => closed_sphere(closest(2, u32::MAX, t, sphere_tris)),
        "soup" => random_soup(t, 0x5eed, (1.0 / math::cbrt(t as f64)) as f32),
        "slivers" => random_slivers(t, 0x5eed),
        "hair" => hair(t.div_ceil(8), 4, 0x5eed),
        _ => return None,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(m: &MeshData) {
        assert!(m.vertices.iter().flatten().all(|c| c.is_finite()));
        let n = m.vertices.len() as u32;
        assert!(m.indices.iter().flatten().all(|&i| i < n));
    }

    /// Every directed edge appears once and its reverse appears once.
    fn is_closed(m: &MeshData) -> bool {
        let mut edges: Vec<(u32, u32)> = m
            .indices
            .iter()
            .flat_map(|&[a, b, c]| [(a, b), (b, c), (c, a)])
            .collect();
        edges.sort_unstable();
        edges.windows(2).all(|w| w[0] != w[1])
            && edges
                .iter()
                .all(|&(a, b)| edges.binary_search(&(b, a)).is_ok())
    }

    /// Six times the signed volume enclosed (positive for outward winding).
    fn volume6(m: &MeshData) -> f32 {
        (0..m.triangle_count())
            .map(|i| {
                let [a, b, c] = m.triangle(i).map(Vec3::from);
                a.dot(b.cross(c))
            })
            .sum()
    }

    fn bits(m: &MeshData) -> (Vec<u32>, Vec<[u32; 3]>) {
        let v = m.vertices.iter().flatten().map(|c| c.to_bits()).collect();
        (v, m.indices.clone())
    }

    #[test]
    fn counts_match_docs() {
        assert_eq!(closed_sphere(5).triangle_count(), 80);
        assert_eq!(closed_sphere(5).vertex_count(), 42);
        assert_eq!(sphereflake(2, 4).triangle_count(), 91 * 48);
        assert_eq!(tetra(3).triangle_count(), 256);
        assert_eq!(mount(3, 1).triangle_count(), 64);
        assert_eq!(mount(3, 1).vertex_count(), 45);
        assert_eq!(rings(5, 12).triangle_count(), 5 * 2 * 12 * 6);
        assert_eq!(gears(3, 10).triangle_count(), 3 * 160);
        assert_eq!(random_soup(17, 3, 0.1).triangle_count(), 17);
        assert_eq!(random_slivers(17, 3).triangle_count(), 17);
        assert_eq!(hair(17, 4, 3).triangle_count(), 17 * 8);
        assert_eq!(hair(17, 4, 3).vertex_count(), 17 * 10);
    }

    #[test]
    fn closed_and_outward() {
        for n in [2, 3, 4, 7, 20] {
            let s = closed_sphere(n);
            check(&s);
            assert!(is_closed(&s), "sphere {n}");
            assert!(volume6(&s) > 0.0);
        }
        for m in [rings(1, 9), gears(1, 7), tetra(0), sphereflake(1, 3)] {
            assert!(is_closed(&m));
            assert!(volume6(&m) > 0.0);
        }
        // Each Sierpinski tetrahedron is closed on its own 4 vertices.
        assert!(is_closed(&tetra(2)));
        assert!(volume6(&tetra(2)) > 0.0);
        assert!(!is_closed(&mount(2, 0)));
    }

    #[test]
    fn by_name_sizes_and_validity() {
        for &name in NAMES {
            for target in [1_000usize, 10_000, 100_000] {
                let m = by_name(name, target).unwrap();
                check(&m);
                let ratio = m.triangle_count() as f64 / target as f64;
                assert!((0.5..=2.0).contains(&ratio), "{name} {target}: {ratio}");
            }
        }
        assert!(by_name("nope", 1000).is_none());
    }

    #[test]
    fn deterministic() {
        for &name in NAMES {
            assert_eq!(
                bits(&by_name(name, 2000).unwrap()),
                bits(&by_name(name, 2000).unwrap())
            );
        }
        assert_ne!(bits(&mount(4, 1)), bits(&mount(4, 2)));
        assert_ne!(
            bits(&random_soup(10, 1, 0.1)),
            bits(&random_soup(10, 2, 0.1))
        );
    }

    #[test]
    fn bounds_of_generators() {
        let inside = |m: &MeshData| {
            let b = m.bounds();
            let (lo, hi) = (b.min.to_array(), b.max.to_array());
            lo.iter().all(|&c| c >= 0.0) && hi.iter().all(|&c| c <= 1.0)
        };
        assert!(inside(&random_soup(1000, 7, 0.05)));
        assert!(inside(&random_slivers(1000, 7)));
        assert!(inside(&hair(1000, 4, 7)));
        let b = teapot_in_stadium(500, 1000).bounds();
        let (lo, hi) = (b.min.to_array(), b.max.to_array());
        assert_eq!((lo, hi), ([-500.0, -300.0, 0.0], [500.0, 300.0, 1.0]));
        assert!(MeshData::default().bounds().is_empty());
    }

    #[test]
    fn append_and_transform() {
        let mut a = closed_sphere(3);
        let b = closed_sphere(4).transformed(2.0, [1.0, 0.0, 0.0]);
        let (na, nb) = (a.vertex_count(), a.triangle_count());
        a.append(&b);
        check(&a);
        assert!(is_closed(&a));
        assert_eq!(a.triangle_count(), nb + b.triangle_count());
        assert_eq!(a.vertices[na], [1.0, 0.0, 2.0]);
        assert_eq!(a.as_source().indices.len(), a.triangle_count());
    }
}
