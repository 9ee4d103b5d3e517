//! Acceleration structures and the one query surface they share.

use crate::mesh::TriMesh;
pub use crate::ray::Aabb;
use crate::ray::{Hit, Ray};
use crate::triangle::packs::TrianglePacks;
use crate::triangle::{Block4, PreparedRay, TriangleLoop, TriangleTest};

pub mod brute;
pub mod grid;
pub mod kdtree;

/// The three questions every structure answers, about the mesh it was built from.
///
/// Guarantees shared by every implementation: the same watertight triangle test
/// ([`crate::triangle::PreparedRay::intersect_triangle`]) and the same tie rule ([`Hit::beats`]), so the
/// closest hit is bit-identical across structures; `occluded` is true exactly when `intersect` hits;
/// neither allocates nor panics, whatever the ray.
pub trait RayQuery {
    /// A box holding every triangle the structure can report.
    fn bounds(&self) -> Aabb;
    /// The closest hit in `[tmin, tmax]`, ties to the lowest primitive id, or [`Hit::MISS`].
    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit;
    /// True when any triangle is hit in `[tmin, tmax]`.
    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool;
}

/// Prepares `ray` for the triangles of `mesh` and runs `walk` with the triangle test specialised for
/// the ray's axes: the one entry of every structure's queries. A ray that can hit nothing (see
/// [`PreparedRay::new`]) is a miss without a walk.
#[inline(always)]
pub(crate) fn run_query<L: TriangleLoop<Output = Hit>>(mesh: &TriMesh, ray: &Ray, walk: L) -> Hit {
    match PreparedRay::new(ray) {
        Some(r) => r.for_scene(mesh.coordinate_bound()).dispatch(walk),
        None => Hit::MISS,
    }
}

/// The lanes `k` of the block starting at reference `base` with `start ≤ base + k < end`.
#[inline(always)]
fn lanes_in(start: usize, end: usize, base: usize) -> u32 {
    let lo = start.saturating_sub(base).min(4);
    let hi = end.saturating_sub(base).min(4);
    ((1u32 << hi) - 1) & !((1u32 << lo) - 1)
}

/// Tests the triangles `ids[start..end]` (a cell's or a leaf's part of a structure's reference
/// list, `packs` built from that list) and keeps the best hit in `best` by the shared tie rule
/// ([`Hit::beats`]). With `ANY`, returns the first hit at once.
///
/// Four at a time: the f32 filter rejects the clear misses of a block and each survivor gets the
/// exact test, so the answer is the one triangle-by-triangle testing gives.
#[inline(always)]
pub(crate) fn test_refs<T: TriangleTest, const ANY: bool>(
    test: &T,
    mesh: &TriMesh,
    packs: &TrianglePacks,
    ids: &[u32],
    start: usize,
    end: usize,
    best: &mut Hit,
) -> Option<Hit> {
    // An empty list at an offset that is not a multiple of 4 must not test the block around it.
    if start >= end {
        return None;
    }
    let mut base = start & !3;
    while base < end {
        let lanes = lanes_in(start, end, base);
        let gathered;
        let block = match packs.block(base / 4) {
            Some(b) => b,
            None => {
                gathered = gather(mesh, ids, base, lanes);
                &gathered
            }
        };
        let mut survivors = test.survivors(block) & lanes;
        while survivors != 0 {
            let lane = survivors.trailing_zeros() as usize;
            survivors &= survivors - 1;
            // The padding of block-aligned lists (never a survivor while the filter runs).
            let Some(&prim) = ids.get(base + lane).filter(|&&p| p != Hit::INVALID_ID) else {
                continue;
            };
            if let Some((t, u, v)) = test.test(&block.get(lane)) {
                let h = Hit { t, u, v, prim };
                if ANY {
                    return Some(h);
                }
                if h.beats(best) {
                    *best = h;
                }
            }
        }
        base += 4;
    }
    None
}

/// The triangles of `ids[base..base + 4]` named by `lanes`, from the mesh (the indexed layout).
/// Out of line: one copy serves every walk, and its call costs little beside the gather itself.
#[inline(never)]
fn gather(mesh: &TriMesh, ids: &[u32], base: usize, lanes: u32) -> Block4 {
    let mut block = Block4::default();
    for lane in 0..4 {
        if lanes & (1 << lane) != 0 {
            if let Some(tri) = ids.get(base + lane).and_then(|&p| mesh.triangle(p)) {
                block.set(lane, tri);
            }
        }
    }
    block
}
