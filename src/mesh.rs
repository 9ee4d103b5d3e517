//! The validated triangle mesh every structure is built from.

use alloc::vec::Vec;
use glam::{Vec3, Vec3A};

use crate::bigvec::BigVec;
use crate::budget::{bytes_of, MemoryBudget};
use crate::error::{BuildError, MeshError};
use crate::ray::Aabb;

/// A triangle mesh that passed validation, stored as three vertices per triangle so that a query reads
/// one contiguous record per triangle test. It may hold several geometries (each a mesh of the
/// caller's), their triangles one after the other in the order given.
///
/// # Guarantees
/// - every coordinate is finite;
/// - there are fewer than `u32::MAX` triangles, so every primitive id fits a `u32` and
///   `Hit::INVALID_ID` is never a real id;
/// - triangle `i` of geometry `g` is triangle `geometry_start(g) + i`, its vertices those of the
///   input, in the input's vertex order;
/// - the vertex indices of every triangle are kept (within their geometry), so that
///   [`TriMesh::set_vertices`] can move a geometry's vertices.
///
/// Functions that receive a `TriMesh` do not check these again.
#[derive(Debug)]
pub struct TriMesh {
    tris: BigVec<[Vec3; 3]>,
    /// Bit `i % 32` of word `i / 32` is set when triangle `i` is degenerate (decided once, here, so
    /// that structures and queries never recompute it).
    degenerate_bits: Vec<u32>,
    bounds: Aabb,
    degenerate: usize,
    /// Each triangle's vertex indices, within its geometry.
    indices: BigVec<[u32; 3]>,
    /// Per geometry, its first triangle; then the triangle count (`geometries + 1` entries).
    starts: Vec<u32>,
    /// Per geometry, its vertex count.
    vertex_counts: Vec<usize>,
}

/// Where a mesh's data comes from: counts plus two accessors, so that C's strided arrays and Rust
/// slices share one validation path.
pub trait MeshSource {
    /// Number of vertices.
    fn vertex_count(&self) -> usize;
    /// Number of triangles.
    fn triangle_count(&self) -> usize;
    /// Vertex `i` (`i < vertex_count()`). The same value every time it is asked: the copy checks
    /// every vertex in one pass and reads them again in the next (a second check per corner cost
    /// the grid's build 4 % of its instructions). A source that answers differently can leave a
    /// non-finite corner in the mesh, whose answers are then unspecified (never unsafe); slices and
    /// the C API's arrays cannot.
    fn vertex(&self, i: usize) -> [f32; 3];
    /// The three vertex indices of triangle `i` (`i < triangle_count()`), not yet checked.
    fn triangle(&self, i: usize) -> [u32; 3];

    /// The first vertex with a coordinate that is not finite, if any. Provided: validation calls
    /// it once per geometry, so that the accessors inline into its loop.
    fn first_non_finite_vertex(&self) -> Option<usize> {
        (0..self.vertex_count()).find(|&i| !Vec3::from(self.vertex(i)).is_finite())
    }

    /// Appends every triangle's corners to `tris` and its indices to `indices`, both with room
    /// for `triangle_count()` more, recording each in `classified` as it goes (one pass over the
    /// triangles, not a second over the copy); or, leaving both as they were, refuses the first
    /// triangle with an index out of range (`classified` may then hold some of the geometry's
    /// triangles: the mesh is dropped). Provided (one call per geometry, the accessors inlined).
    fn copy_triangles(
        &self,
        tris: &mut BigVec<[Vec3; 3]>,
        indices: &mut BigVec<[u32; 3]>,
        classified: &mut Classified<'_>,
    ) -> Result<(), MeshError> {
        let (n, nv) = (self.triangle_count(), self.vertex_count());
        let first = tris.len();
        let (Some(corners), Some(ids)) = (
            tris.spare_capacity_mut().get_mut(..n),
            indices.spare_capacity_mut().get_mut(..n),
        ) else {
            return Err(MeshError::CountOverflow {
                what: "triangle count",
            });
        };
        for (i, (corner, id)) in corners.iter_mut().zip(ids.iter_mut()).enumerate() {
            let idx = self.triangle(i);
            if idx[0].max(idx[1]).max(idx[2]) as usize >= nv {
                return Err(index_out_of_range(i, idx, nv));
            }
            id.write(idx);
            let tri = idx.map(|vi| Vec3::from(self.vertex(vi as usize)));
            classified.record(first + i, &tri);
            corner.write(tri);
        }
        let (t, x) = (tris.len() + n, indices.len() + n);
        // SAFETY: the first `n` slots past each length were written above, and both vectors have
        // room for them (`get_mut(..n)` succeeded).
        unsafe {
            tris.set_len(t);
            indices.set_len(x);
        }
        Ok(())
    }

    /// The first triangle with an index out of range, if any (what [`MeshSource::copy_triangles`]
    /// would refuse), without copying.
    fn first_bad_index(&self) -> Option<MeshError> {
        let nv = self.vertex_count();
        (0..self.triangle_count()).find_map(|i| {
            let idx = self.triangle(i);
            (idx[0].max(idx[1]).max(idx[2]) as usize >= nv).then(|| index_out_of_range(i, idx, nv))
        })
    }
}

/// The refusal of triangle `triangle`, whose indices `idx` include one not below `vertex_count`.
#[cold]
fn index_out_of_range(triangle: usize, idx: [u32; 3], vertex_count: usize) -> MeshError {
    let index = idx
        .into_iter()
        .find(|&vi| vi as usize >= vertex_count)
        .unwrap_or(u32::MAX);
    MeshError::IndexOutOfRange {
        triangle,
        index,
        vertex_count,
    }
}

/// What [`MeshSource::copy_triangles`] learns of the triangles it copies: which are degenerate (in
/// the mesh's flag words, clear before the copy), how many, and the bounds of the others. Made and
/// read by [`TriMesh`] alone.
#[derive(Debug)]
pub struct Classified<'a> {
    flags: &'a mut [u32],
    degenerate: usize,
    lo: Vec3A,
    hi: Vec3A,
}

impl<'a> Classified<'a> {
    fn new(flags: &'a mut [u32]) -> Self {
        Classified {
            flags,
            degenerate: 0,
            lo: Vec3A::INFINITY,
            hi: Vec3A::NEG_INFINITY,
        }
    }

    /// Triangle `i` (`tri`, finite coordinates), whose flag is clear: flagged if degenerate,
    /// otherwise taken into the bounds.
    #[inline(always)]
    fn record(&mut self, i: usize, tri: &[Vec3; 3]) {
        // The f64 product first (exact enough for nearly every triangle: non-zero means area),
        // and where it is zero the exact one, since f64 rounds a tiny edge against a huge one
        // away (a review's tetrahedron with corners at 2^30 and 2^-30 lost a face of area ~1 and
        // leaked rays).
        if edge_cross(tri) == glam::DVec3::ZERO && crate::triangle::edge_cross_is_zero(tri) {
            if let Some(word) = self.flags.get_mut(i / 32) {
                *word |= 1 << (i % 32);
            }
            self.degenerate += 1;
        } else {
            self.include(tri);
        }
    }

    /// Whether triangle `i`'s flag is set.
    #[inline(always)]
    fn flagged(&self, i: usize) -> bool {
        self.flags
            .get(i / 32)
            .is_some_and(|w| w & (1 << (i % 32)) != 0)
    }

    /// A triangle that is not degenerate, taken into the bounds. Four lanes at a time (the fourth
    /// unused); coordinates are finite, so `min`/`max` need no NaN handling.
    #[inline(always)]
    fn include(&mut self, tri: &[Vec3; 3]) {
        let [p, q, r] = tri.map(Vec3A::from);
        self.lo = self.lo.min(p.min(q).min(r));
        self.hi = self.hi.max(p.max(q).max(r));
    }

    fn bounds(&self) -> Aabb {
        Aabb {
            min: self.lo.into(),
            max: self.hi.into(),
        }
    }
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
        TriMesh::from_sources(&[src], budget).map_err(|e| match e {
            BuildError::InvalidGeometry { error, .. } => BuildError::InvalidMesh(error),
            other => other,
        })
    }

    /// Validates the geometries `sources` and copies their triangles one after the other, charging
    /// the copy to `budget`; a refusal says which geometry ([`BuildError::InvalidGeometry`]).
    pub fn from_sources(
        sources: &[&dyn MeshSource],
        budget: &mut MemoryBudget,
    ) -> Result<TriMesh, BuildError> {
        // Refusals come in geometry order, and within a geometry vertices before indices; the
        // indices are checked while they are copied, so a failed allocation looks for a bad index
        // first (a refused mesh is refused whatever the memory limit).
        let refusal = |upto: usize| {
            sources.iter().take(upto).enumerate().find_map(|(g, src)| {
                src.first_non_finite_vertex()
                    .map(|vertex| MeshError::NonFiniteVertex { vertex })
                    .or_else(|| src.first_bad_index())
                    .map(|error| BuildError::InvalidGeometry { geometry: g, error })
            })
        };
        let mut n = 0usize;
        for (g, src) in sources.iter().enumerate() {
            n = n.saturating_add(src.triangle_count());
            let bad = |error| BuildError::InvalidGeometry { geometry: g, error };
            if n >= u32::MAX as usize || n.checked_mul(core::mem::size_of::<[Vec3; 3]>()).is_none()
            {
                return Err(refusal(g).unwrap_or(bad(MeshError::CountOverflow {
                    what: "triangle count",
                })));
            }
        }
        let mut mesh = TriMesh {
            tris: BigVec::new(),
            degenerate_bits: Vec::new(),
            bounds: Aabb::EMPTY,
            degenerate: 0,
            indices: BigVec::new(),
            starts: Vec::new(),
            vertex_counts: Vec::new(),
        };
        let allocated = (|| {
            mesh.tris = budget.big_vec(n, "mesh triangles")?;
            mesh.degenerate_bits = budget.filled(n.div_ceil(32), 0u32, "mesh degenerate flags")?;
            mesh.indices = budget.big_vec(n, "mesh indices")?;
            mesh.starts = budget.vec(sources.len() + 1, "mesh geometries")?;
            mesh.vertex_counts = budget.vec(sources.len(), "mesh geometries")?;
            Ok::<(), BuildError>(())
        })();
        if let Err(e) = allocated {
            mesh.release(budget);
            return Err(refusal(sources.len()).unwrap_or(e));
        }
        let mut classified = Classified::new(&mut mesh.degenerate_bits);
        for (g, src) in sources.iter().enumerate() {
            let start = mesh.tris.len();
            let copied = match src.first_non_finite_vertex() {
                Some(vertex) => Err(MeshError::NonFiniteVertex { vertex }),
                None => src.copy_triangles(&mut mesh.tris, &mut mesh.indices, &mut classified),
            };
            // `copy_triangles` may be overridden: one that copies another count than the source
            // says is refused, as the triangles and indices must stay in step.
            let end = start.saturating_add(src.triangle_count());
            let copied = copied.and_then(|()| {
                if mesh.tris.len() == end && mesh.indices.len() == end {
                    Ok(())
                } else {
                    Err(MeshError::MissingData {
                        what: "copied triangles",
                    })
                }
            });
            if let Err(error) = copied {
                mesh.release(budget);
                return Err(BuildError::InvalidGeometry { geometry: g, error });
            }
            mesh.starts.push(start as u32);
            mesh.vertex_counts.push(src.vertex_count());
        }
        mesh.starts.push(mesh.tris.len() as u32);
        (mesh.degenerate, mesh.bounds) = (classified.degenerate, classified.bounds());
        Ok(mesh)
    }

    /// Recomputes the degenerate flags of triangles `range`, then the count and the bounds, in
    /// one pass over the triangles (each read once for its flag and the bounds).
    fn classify(&mut self, range: core::ops::Range<usize>) {
        let range = range.start..range.end.min(self.tris.len());
        for i in range.clone() {
            if let Some(word) = self.degenerate_bits.get_mut(i / 32) {
                *word &= !(1 << (i % 32));
            }
        }
        // The others' flags stay as they are: read, counted, and their triangles' bounds taken.
        let mut classified = Classified::new(&mut self.degenerate_bits);
        for (i, tri) in self.tris.iter().enumerate() {
            if range.contains(&i) {
                classified.record(i, tri);
            } else if classified.flagged(i) {
                classified.degenerate += 1;
            } else {
                classified.include(tri);
            }
        }
        (self.degenerate, self.bounds) = (classified.degenerate, classified.bounds());
    }

    /// Number of geometries.
    pub fn geometry_count(&self) -> usize {
        self.vertex_counts.len()
    }

    /// Vertices of geometry `g` as its source gave them (`None` for no such geometry).
    pub fn geometry_vertex_count(&self, g: usize) -> Option<usize> {
        self.vertex_counts.get(g).copied()
    }

    /// The first triangle of geometry `g` (and, for `g = geometry_count()`, the triangle count).
    pub fn geometry_start(&self, g: usize) -> u32 {
        self.starts
            .get(g)
            .copied()
            .unwrap_or(self.tris.len() as u32)
    }

    /// The geometry of triangle `prim` and the triangle's index within it (`None` for no such
    /// triangle).
    #[inline]
    pub fn geometry_of(&self, prim: u32) -> Option<(u32, u32)> {
        if prim as usize >= self.tris.len() {
            return None;
        }
        // The last start not above `prim` (geometries without triangles share a start).
        let g = self
            .starts
            .partition_point(|&s| s <= prim)
            .saturating_sub(1);
        Some((g as u32, prim - self.starts[g]))
    }

    /// New positions for the vertices of geometry `g` (`vertex(i)` for each of its
    /// `vertex_count`): same count and topology. Refuses a non-finite coordinate, of any vertex
    /// (nothing changes then) or of a corner as it is written (a `vertex` that answers differently
    /// when asked again: the geometry's triangles are then partly moved and its flags and the
    /// bounds stale, for the caller to restore with [`TriMesh::restore_triangles`], as
    /// `Scene::set_vertices` does); afterwards the triangles, degenerate flags and bounds are those
    /// of the moved mesh.
    pub(crate) fn set_vertices(
        &mut self,
        g: usize,
        vertex: &dyn Fn(usize) -> [f32; 3],
    ) -> Result<(), BuildError> {
        let Some(&count) = self.vertex_counts.get(g) else {
            return Err(BuildError::InvalidArgument {
                what: "no such geometry",
            });
        };
        for vi in 0..count {
            if !Vec3::from(vertex(vi)).is_finite() {
                return Err(BuildError::InvalidGeometry {
                    geometry: g,
                    error: MeshError::NonFiniteVertex { vertex: vi },
                });
            }
        }
        let range = self.geometry_start(g) as usize..self.geometry_start(g + 1) as usize;
        for i in range.clone() {
            let idx = self.indices[i];
            let tri = idx.map(|vi| Vec3::from(vertex(vi as usize)));
            if let Some(k) = (0..3).find(|&k| !tri[k].is_finite()) {
                return Err(BuildError::InvalidGeometry {
                    geometry: g,
                    error: MeshError::NonFiniteVertex {
                        vertex: idx[k] as usize,
                    },
                });
            }
            self.tris[i] = tri;
        }
        self.classify(range);
        Ok(())
    }

    /// Puts back the triangles of geometry `g` as `saved` held them (its triangles before a
    /// [`TriMesh::set_vertices`]), with their flags and the bounds.
    pub(crate) fn restore_triangles(&mut self, g: usize, saved: &[[Vec3; 3]]) {
        let start = self.geometry_start(g) as usize;
        let end = (start + saved.len()).min(self.tris.len());
        self.tris[start..end].copy_from_slice(&saved[..end - start]);
        self.classify(start..end);
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

    /// Bytes this mesh holds.
    pub fn memory_bytes(&self) -> usize {
        self.tris.bytes()
            + bytes_of(&self.degenerate_bits)
            + self.indices.bytes()
            + bytes_of(&self.starts)
            + bytes_of(&self.vertex_counts)
    }

    /// Gives the copy's bytes back to the budget it was charged to and drops it.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free_big(self.tris);
        budget.free(self.degenerate_bits);
        budget.free_big(self.indices);
        budget.free(self.starts);
        budget.free(self.vertex_counts);
    }
}

/// The edge cross product `(p1 − p0) × (p2 − p0)` in f64 from the f32 coordinates: non-zero means
/// the triangle has area (a rounded product is zero only if the exact one is tiny against its
/// terms); zero is confirmed exactly before a triangle is flagged degenerate (`Classified::record`,
/// the one place that decides it for every structure).
#[inline(always)]
fn edge_cross(t: &[Vec3; 3]) -> glam::DVec3 {
    let e1 = t[1].as_dvec3() - t[0].as_dvec3();
    let e2 = t[2].as_dvec3() - t[0].as_dvec3();
    e1.cross(e2)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::SplitMix64;

    /// `count` random triangles, each with its own three vertices; every fifth has its third
    /// corner at its second's position (degenerate until its vertices move apart).
    fn part(count: usize, rng: &mut SplitMix64) -> MeshData {
        let mut data = MeshData::default();
        for i in 0..count {
            let b = data.vertices.len() as u32;
            let mut corner = || [rng.next_f32(), rng.next_f32(), rng.next_f32()];
            let (p, q) = (corner(), corner());
            data.vertices
                .extend([p, q, if i % 5 == 0 { q } else { corner() }]);
            data.indices.push([b, b + 1, b + 2]);
        }
        data
    }

    fn mesh_of(parts: &[MeshData]) -> TriMesh {
        let sources: Vec<IndexedMesh<'_>> = parts.iter().map(MeshData::as_source).collect();
        let dyns: Vec<&dyn MeshSource> = sources.iter().map(|s| s as &dyn MeshSource).collect();
        TriMesh::from_sources(&dyns, &mut MemoryBudget::new(0)).unwrap()
    }

    /// Moving one geometry whose triangles straddle flag words leaves the flags, their count and the
    /// bounds those of a fresh copy of the moved geometries: the moved range's flags are made anew
    /// (triangles that become degenerate and ones that stop being), the other geometries' kept.
    #[test]
    fn a_move_classifies_as_a_fresh_copy() {
        let mut rng = SplitMix64::new(5);
        let mut parts = [37, 50, 20].map(|n| part(n, &mut rng));
        let mut mesh = mesh_of(&parts);
        let before = mesh.degenerate_count();
        assert_eq!(before, 8 + 10 + 4);
        // Every vertex moved out to new random places, then every third triangle collapsed (from
        // the third: mesh triangle 63, the last of a flag word, among them).
        let mut moved: Vec<[f32; 3]> = (0..parts[1].vertices.len())
            .map(|_| [rng.next_f32(), rng.next_f32(), rng.next_f32()].map(|c| c * 7.0 - 3.0))
            .collect();
        for t in (2..50).step_by(3) {
            moved[3 * t + 2] = moved[3 * t];
        }
        mesh.set_vertices(1, &|i| moved[i]).unwrap();
        parts[1].vertices = moved;
        let fresh = mesh_of(&parts);
        assert_eq!(mesh.degenerate_bits(), fresh.degenerate_bits());
        assert_eq!(mesh.degenerate_count(), fresh.degenerate_count());
        assert_eq!(mesh.bounds(), fresh.bounds());
        // Geometry 1 went from 10 degenerate triangles (every fifth) to 16 (every third).
        assert_eq!(mesh.degenerate_count(), before - 10 + 16);
        assert!(mesh.is_degenerate(63) && !mesh.is_degenerate(62));
        assert!(mesh.bounds().min.x < -1.0 && mesh.bounds().max.x > 2.0);
    }

    /// A source whose `copy_triangles` override copies fewer triangles than it counts is refused
    /// (the triangles and their indices must stay in step), and the budget gets everything back.
    #[test]
    fn a_source_that_copies_too_few_triangles_is_refused() {
        struct Short<'a>(IndexedMesh<'a>);
        impl MeshSource for Short<'_> {
            fn vertex_count(&self) -> usize {
                self.0.vertex_count()
            }
            fn triangle_count(&self) -> usize {
                self.0.triangle_count()
            }
            fn vertex(&self, i: usize) -> [f32; 3] {
                self.0.vertex(i)
            }
            fn triangle(&self, i: usize) -> [u32; 3] {
                self.0.triangle(i)
            }
            fn copy_triangles(
                &self,
                _tris: &mut BigVec<[Vec3; 3]>,
                _indices: &mut BigVec<[u32; 3]>,
                _classified: &mut Classified<'_>,
            ) -> Result<(), MeshError> {
                Ok(())
            }
        }
        let data = part(4, &mut SplitMix64::new(9));
        let whole = IndexedMesh {
            vertices: &data.vertices,
            indices: &data.indices,
        };
        let mut budget = MemoryBudget::new(0);
        assert!(TriMesh::from_sources(&[&whole], &mut budget).is_ok());
        let mut budget = MemoryBudget::new(0);
        let refused = TriMesh::from_sources(&[&whole, &Short(whole)], &mut budget);
        assert!(matches!(
            refused,
            Err(BuildError::InvalidGeometry {
                geometry: 1,
                error: MeshError::MissingData { .. }
            })
        ));
        assert_eq!(budget.used(), 0);
    }
}
