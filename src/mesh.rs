//! The validated triangle mesh every structure is built from.

use alloc::vec::Vec;
use glam::Vec3;

use crate::budget::{bytes_of, MemoryBudget};
use crate::error::{BuildError, MeshError};
use crate::ray::Aabb;

/// A triangle mesh that passed validation, stored as three vertices per triangle so that a query reads
/// one contiguous record per triangle test.
///
/// # Guarantees
/// - every coordinate is finite;
/// - there are fewer than `u32::MAX` triangles, so every primitive id fits a `u32` and
///   `Hit::INVALID_ID` is never a real id;
/// - triangle `i` is the `i`-th triangle of the input, in the input's vertex order.
///
/// Functions that receive a `TriMesh` do not check these again.
#[derive(Debug)]
pub struct TriMesh {
    tris: Vec<[Vec3; 3]>,
    /// Bit `i % 32` of word `i / 32` is set when triangle `i` is degenerate (decided once, here, so
    /// that structures and queries never recompute it).
    degenerate_bits: Vec<u32>,
    bounds: Aabb,
    degenerate: usize,
}

/// Where a mesh's data comes from: counts plus two accessors, so that C's strided arrays and Rust
/// slices share one validation path.
pub trait MeshSource {
    /// Number of vertices.
    fn vertex_count(&self) -> usize;
    /// Number of triangles.
    fn triangle_count(&self) -> usize;
    /// Vertex `i` (`i < vertex_count()`).
    fn vertex(&self, i: usize) -> [f32; 3];
    /// The three vertex indices of triangle `i` (`i < triangle_count()`), not yet checked.
    fn triangle(&self, i: usize) -> [u32; 3];
}

/// An indexed mesh borrowed from Rust slices.
#[derive(Clone, Copy, Debug)]
pub struct IndexedMesh<'a> {
    /// Vertex positions.
    pub vertices: &'a [[f32; 3]],
    /// Vertex indices, three per triangle.
    pub indices: &'a [[u32; 3]],
}

impl MeshSource for IndexedMesh<'_> {
    fn vertex_count(&self) -> usize {
        self.vertices.len()
    }
    fn triangle_count(&self) -> usize {
        self.indices.len()
    }
    fn vertex(&self, i: usize) -> [f32; 3] {
        self.vertices[i]
    }
    fn triangle(&self, i: usize) -> [u32; 3] {
        self.indices[i]
    }
}

impl TriMesh {
    /// Validates `src` and copies its triangles, charging the copy to `budget`.
    ///
    /// Refuses non-finite coordinates (of any vertex, used or not), indices out of range, and
    /// triangle counts that do not fit 32-bit ids. Degenerate triangles (repeated or collinear
    /// vertices) are kept and will never be hit. An empty mesh is valid.
    pub fn from_source(
        src: &impl MeshSource,
        budget: &mut MemoryBudget,
    ) -> Result<TriMesh, BuildError> {
        let n = src.triangle_count();
        let nv = src.vertex_count();
        if n >= u32::MAX as usize {
            return Err(MeshError::CountOverflow {
                what: "triangle count",
            }
            .into());
        }
        if n.checked_mul(core::mem::size_of::<[Vec3; 3]>()).is_none() {
            return Err(MeshError::CountOverflow {
                what: "triangle count",
            }
            .into());
        }
        for vi in 0..nv {
            if !Vec3::from(src.vertex(vi)).is_finite() {
                return Err(MeshError::NonFiniteVertex { vertex: vi }.into());
            }
        }
        let mut tris = budget.vec::<[Vec3; 3]>(n, "mesh triangles")?;
        let mut degenerate_bits = match budget.filled(n.div_ceil(32), 0u32, "mesh degenerate flags")
        {
            Ok(b) => b,
            Err(e) => {
                budget.free(tris);
                return Err(e);
            }
        };
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let mut degenerate = 0;
        for i in 0..n {
            let idx = src.triangle(i);
            if let Some(&vi) = idx.iter().find(|&&vi| vi as usize >= nv) {
                budget.free(tris);
                budget.free(degenerate_bits);
                return Err(MeshError::IndexOutOfRange {
                    triangle: i,
                    index: vi,
                    vertex_count: nv,
                }
                .into());
            }
            let tri = idx.map(|vi| Vec3::from(src.vertex(vi as usize)));
            if is_degenerate(&tri) {
                degenerate += 1;
                if let Some(w) = degenerate_bits.get_mut(i / 32) {
                    *w |= 1 << (i % 32);
                }
            } else {
                lo = lo.min(tri[0]).min(tri[1]).min(tri[2]);
                hi = hi.max(tri[0]).max(tri[1]).max(tri[2]);
            }
            tris.push(tri);
        }
        Ok(TriMesh {
            tris,
            degenerate_bits,
            bounds: Aabb { min: lo, max: hi },
            degenerate,
        })
    }

    /// Validates and copies an indexed mesh given as Rust slices.
    pub fn new(
        vertices: &[[f32; 3]],
        indices: &[[u32; 3]],
        budget: &mut MemoryBudget,
    ) -> Result<TriMesh, BuildError> {
        TriMesh::from_source(&IndexedMesh { vertices, indices }, budget)
    }

    /// Number of triangles (degenerate ones included).
    pub fn len(&self) -> usize {
        self.tris.len()
    }

    /// True when the mesh has no triangles.
    pub fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// The three vertices of triangle `prim`, or `None` when there is no such triangle.
    #[inline(always)]
    pub fn triangle(&self, prim: u32) -> Option<&[Vec3; 3]> {
        self.tris.get(prim as usize)
    }

    /// All triangles in id order.
    pub fn triangles(&self) -> &[[Vec3; 3]] {
        &self.tris
    }

    /// True when triangle `prim` can never be hit (repeated or collinear vertices); structures leave
    /// such triangles out.
    #[inline]
    pub fn is_degenerate(&self, prim: u32) -> bool {
        self.degenerate_bits
            .get(prim as usize / 32)
            .map_or(true, |w| w & (1 << (prim % 32)) != 0)
            || prim as usize >= self.tris.len()
    }

    /// The degenerate flags: bit `i % 32` of word `i / 32` is set when triangle `i` is degenerate
    /// (`triangles().len().div_ceil(32)` words; bits past the last triangle are clear).
    #[inline]
    pub fn degenerate_bits(&self) -> &[u32] {
        &self.degenerate_bits
    }

    /// How many triangles are degenerate.
    pub fn degenerate_count(&self) -> usize {
        self.degenerate
    }

    /// Bounds of the non-degenerate triangles ([`Aabb::EMPTY`] when there are none).
    pub fn bounds(&self) -> Aabb {
        self.bounds
    }

    /// The largest coordinate magnitude of the non-degenerate triangles (`+∞` when there are none):
    /// what structures pass to the triangle test's per-ray bound.
    #[inline]
    pub fn coordinate_bound(&self) -> f32 {
        self.bounds
            .min
            .abs()
            .max(self.bounds.max.abs())
            .max_element()
    }

    /// Bytes this mesh holds.
    pub fn memory_bytes(&self) -> usize {
        bytes_of(&self.tris) + bytes_of(&self.degenerate_bits)
    }

    /// Gives the copy's bytes back to the budget it was charged to and drops it.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.tris);
        budget.free(self.degenerate_bits);
    }
}

/// Zero area, decided exactly enough that every structure agrees: the edge cross product, computed in
/// f64 from the f32 coordinates, is exactly zero.
#[inline]
fn is_degenerate(t: &[Vec3; 3]) -> bool {
    let e1 = t[1].as_dvec3() - t[0].as_dvec3();
    let e2 = t[2].as_dvec3() - t[0].as_dvec3();
    e1.cross(e2) == glam::DVec3::ZERO
}

/// An owned indexed mesh (vertex positions plus three indices per triangle), as loaders and the
/// procedural generator produce it. Not validated: build a [`TriMesh`] from it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    /// Vertex positions.
    pub vertices: Vec<[f32; 3]>,
    /// Vertex indices, three per triangle.
    pub indices: Vec<[u32; 3]>,
}

impl MeshData {
    /// Appends the quad with corners `p` (0–3 a diagonal) as the two triangles (0, 1, 2), (2, 1, 3).
    pub fn push_quad(&mut self, p: [[f32; 3]; 4]) {
        let b = self.vertices.len() as u32;
        self.vertices.extend(p);
        self.indices
            .extend([[b, b + 1, b + 2], [b + 2, b + 1, b + 3]]);
    }

    /// Borrows the data as a [`MeshSource`].
    pub fn as_source(&self) -> IndexedMesh<'_> {
        IndexedMesh {
            vertices: &self.vertices,
            indices: &self.indices,
        }
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len()
    }

    /// The box around every vertex ([`Aabb::EMPTY`] when there is none).
    pub fn bounds(&self) -> Aabb {
        self.vertices
            .iter()
            .fold(Aabb::EMPTY, |b, &v| b.grow(Vec3::from(v)))
    }
}
