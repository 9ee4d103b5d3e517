//! Acceleration structures and the one query surface they share.

use glam::Vec3;

use crate::mesh::TriMesh;
pub use crate::ray::Aabb;
use crate::ray::{Hit, Ray};
use crate::triangle::packs::{TriangleLayout, TrianglePacks};
use crate::triangle::{Accept, Block4, PreparedRay, TriHit, TriangleLoop, TriangleTest};

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

/// The queries of [`RayQuery`] with conditions on hits (masks, culling, filters: see
/// [`crate::geometry`]): a hit counts only when `accept` says so (`None`: every hit counts, the
/// plain query), and the closest such hit is the answer. Conditions are asked once per exact hit,
/// not per triangle test.
pub(crate) trait AcceptingQuery {
    /// The closest hit `accept` counts, ties to the lowest primitive id, or [`Hit::MISS`].
    fn intersect_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> Hit;
    /// True when any hit `accept` counts is in `[tmin, tmax]`.
    fn occluded_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> bool;
}

/// Prepares `ray` for the triangles of `mesh` and runs `walk` with the triangle test specialised for
/// the ray's axes (and the query's conditions on hits, `accept`): the one entry of every
/// structure's queries. `held` is a box holding the triangles the structure holds copies of (its
/// bounds; [`Aabb::EMPTY`] for a walk that reads only `mesh`): the filter's per-ray bound needs a
/// box holding every triangle it is given, and a structure's copies are those of the mesh it was
/// built over, which need not be `mesh` now. A ray that can hit nothing (see [`PreparedRay::new`])
/// is a miss without a walk.
#[inline(always)]
pub(crate) fn run_query<L: TriangleLoop<Output = Hit>>(
    mesh: &TriMesh,
    held: Aabb,
    ray: &Ray,
    accept: Option<&dyn Accept>,
    walk: L,
) -> Hit {
    match PreparedRay::prepare(ray, &mesh.bounds().union(held)) {
        Some(r) => r.dispatch_accepting(accept, walk),
        None => Hit::MISS,
    }
}

/// [`run_query`] for a walk that starts by clipping the ray to its structure's box: `walk` makes it
/// from the ray, or returns `None` when the ray misses the box, which is then a miss without the
/// ray being prepared for the triangle test (the shear, the f64 constants, the filter's lanes:
/// 9–20 ns for a missed box instead of 35–70, docs/performance.md, "Stop 34"). `walk` may see a
/// ray that [`PreparedRay::new`] refuses; the query refuses it after.
#[inline(always)]
pub(crate) fn run_clipped_query<L: TriangleLoop<Output = Hit>>(
    mesh: &TriMesh,
    held: Aabb,
    ray: &Ray,
    accept: Option<&dyn Accept>,
    walk: impl FnOnce(&Ray) -> Option<L>,
) -> Hit {
    match walk(ray) {
        Some(walk) => run_query(mesh, held, ray, accept, walk),
        None => Hit::MISS,
    }
}

/// Whether `test_refs` skips triangles the query already tested (measured: docs/performance.md).
const MAILBOX: bool = true;

/// The lanes `k` of the block starting at reference `base` with `start ≤ base + k < end`.
#[inline(always)]
fn lanes_in(start: usize, end: usize, base: usize) -> u32 {
    let lo = start.saturating_sub(base).min(4);
    let hi = end.saturating_sub(base).min(4);
    ((1u32 << hi) - 1) & !((1u32 << lo) - 1)
}

/// The triangles one query has already tested (a ring of the last eight), so that one listed in
/// several cells or leaves is tested once: the test's answer for a ray and a triangle never changes,
/// and the best hit already holds it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Mailbox {
    ids: [u32; 8],
    next: usize,
}

impl Mailbox {
    /// An empty mailbox.
    #[inline(always)]
    pub(crate) fn new() -> Self {
        Mailbox {
            ids: [Hit::INVALID_ID; 8],
            next: 0,
        }
    }

    /// True when `prim` was tested; otherwise records it (evicting the oldest).
    #[inline(always)]
    fn seen(&mut self, prim: u32) -> bool {
        if self.ids.contains(&prim) {
            return true;
        }
        self.ids[self.next & 7] = prim;
        self.next = self.next.wrapping_add(1);
        false
    }
}

/// A structure's reference list and the packs of its triangles (built from that list, or empty for
/// the indexed layout).
///
/// With packs, every list handed to [`test_refs`] starts on a block (a multiple of 4) and the lanes
/// past its end in its last block are padding (`Hit::INVALID_ID`, NaN in the packs): the kd-tree's
/// packed leaves are laid out so.
#[derive(Clone, Copy)]
pub(crate) struct Refs<'a> {
    /// Triangle ids, cell by cell or leaf by leaf.
    pub ids: &'a [u32],
    /// Their triangles, four to a block in the same order.
    pub packs: &'a TrianglePacks,
}

/// Tests the triangles `refs.ids[start..end]` (a cell's or a leaf's part of the list) and keeps the best hit in `best` by the shared tie rule
/// ([`Hit::beats`]). With `ANY`, returns the first hit at once.
///
/// Four at a time: the f32 filter rejects the clear misses of a block and each survivor gets the
/// exact test, so the answer is the one triangle-by-triangle testing gives.
#[inline(always)]
pub(crate) fn test_refs<T: TriangleTest, const ANY: bool>(
    test: &T,
    mesh: &TriMesh,
    refs: Refs<'_>,
    (start, end): (usize, usize),
    best: &mut Hit,
    mailbox: &mut Mailbox,
) -> Option<Hit> {
    let Refs { ids, packs } = refs;
    // An empty list at an offset that is not a multiple of 4 must not test the block around it.
    if start >= end {
        return None;
    }
    debug_assert!(packs.layout() == TriangleLayout::Indexed || start % 4 == 0);
    // Packed lists start on a block and their last block's other lanes are padding (NaN, rejected
    // by the filter; id INVALID or past the list, skipped when the filter is off): whole blocks,
    // read in one pass with no per-block lookup. Otherwise (the indexed layout) each block is
    // gathered from the mesh, with a mask for the lanes in the list.
    if let Some(blocks) = packs.blocks(start / 4, end.div_ceil(4)) {
        let id = |block: usize, lane: usize| {
            ids.get(start + 4 * block + lane)
                .copied()
                .unwrap_or(Hit::INVALID_ID)
        };
        return test_blocks::<T, ANY>(test, blocks, id, best, mailbox);
    }
    let mut base = start & !3;
    while base < end {
        let lanes = lanes_in(start, end, base);
        let block = gather(mesh, ids, base, lanes);
        let survivors = test.survivors(&block) & lanes;
        let id = |lane: usize| ids.get(base + lane).copied().unwrap_or(Hit::INVALID_ID);
        if let Some(h) = test_lanes::<T, ANY>(test, &block, survivors, id, best, mailbox) {
            return Some(h);
        }
        base += 4;
    }
    None
}

/// The hit of triangle `prim` (corners `tri`) if the ray hits it and the query counts the hit.
#[inline(always)]
pub(crate) fn counted_hit<T: TriangleTest>(test: &T, prim: u32, tri: &[Vec3; 3]) -> Option<Hit> {
    counted(test, prim, test.test(tri)?)
}

/// `hit` of triangle `prim` as a [`Hit`] if the query counts it.
#[inline(always)]
fn counted<T: TriangleTest>(test: &T, prim: u32, hit: TriHit) -> Option<Hit> {
    test.accept(prim, &hit).then_some(Hit {
        t: hit.t,
        u: hit.u,
        v: hit.v,
        prim,
    })
}

/// Tests whole blocks of a block-aligned list: lane `k` of `tris[b]` holds the triangle `id(b, k)`
/// (`Hit::INVALID_ID` and NaN in unused lanes). The same answer as [`test_refs`] on the same list:
/// the best hit kept in `best` by [`Hit::beats`], or with `ANY` the first hit at once.
#[inline(always)]
pub(crate) fn test_blocks<T: TriangleTest, const ANY: bool>(
    test: &T,
    tris: &[Block4],
    id: impl Fn(usize, usize) -> u32,
    best: &mut Hit,
    mailbox: &mut Mailbox,
) -> Option<Hit> {
    // Two blocks per pass of the filter where the kernel filters pairs (the last block of an odd
    // list then goes alone below); otherwise one at a time.
    let mut single_from = 0;
    if T::PAIRS {
        for (p, pair) in tris.chunks_exact(2).enumerate() {
            let survivors = test.survivors_pair(&pair[0], &pair[1]);
            if survivors == 0 {
                continue;
            }
            for (half, block) in pair.iter().enumerate() {
                let lanes = (survivors >> (4 * half)) & 0b1111;
                let id = |lane: usize| id(2 * p + half, lane);
                if lanes != 0 {
                    if let Some(h) = test_lanes::<T, ANY>(test, block, lanes, id, best, mailbox) {
                        return Some(h);
                    }
                }
            }
        }
        single_from = tris.len() & !1;
    }
    for (b, block) in tris.iter().enumerate().skip(single_from) {
        let survivors = test.survivors(block);
        if survivors == 0 {
            continue;
        }
        let id = |lane: usize| id(b, lane);
        if let Some(h) = test_lanes::<T, ANY>(test, block, survivors, id, best, mailbox) {
            return Some(h);
        }
    }
    None
}

/// The exact test on the lanes `survivors` of `block` whose id (`id(lane)`) is a real triangle not
/// yet tested by this query (the mailbox), keeping the best hit in `best`; with `ANY`, returns the
/// first hit at once.
#[inline(always)]
fn test_lanes<T: TriangleTest, const ANY: bool>(
    test: &T,
    block: &Block4,
    mut survivors: u32,
    id: impl Fn(usize) -> u32,
    best: &mut Hit,
    mailbox: &mut Mailbox,
) -> Option<Hit> {
    while survivors != 0 {
        let lane = survivors.trailing_zeros() as usize;
        survivors &= survivors - 1;
        let prim = id(lane);
        // The padding of block-aligned lists (never a survivor while the filter runs).
        if prim == Hit::INVALID_ID {
            continue;
        }
        if MAILBOX && mailbox.seen(prim) {
            continue;
        }
        let hit = test.test_lane(block, lane);
        if let Some(h) = hit.and_then(|hit| counted(test, prim, hit)) {
            if ANY {
                return Some(h);
            }
            if h.beats(best) {
                *best = h;
            }
        }
    }
    None
}

/// The triangles of `ids[base..base + 4]` named by `lanes`, from the mesh (the indexed layout).
/// Out of line: one copy serves every walk, and its call costs little beside the gather itself.
#[inline(never)]
fn gather(mesh: &TriMesh, ids: &[u32], base: usize, lanes: u32) -> Block4 {
    let ids = core::array::from_fn(|lane| {
        let named = ids.get(base + lane).copied().unwrap_or(Hit::INVALID_ID);
        if lanes & (1 << lane) != 0 {
            named
        } else {
            Hit::INVALID_ID
        }
    });
    Block4::gather(mesh.triangles(), ids)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::brute::test_all;
    use crate::budget::MemoryBudget;
    use crate::triangle::packs::TriangleLayout;
    use crate::triangle::testgen::pair;
    use crate::workload::SplitMix64;

    /// Both answers of the list test on `ids[start..end]` (closest, any) for `ray`, as queries
    /// run it (`plain == false`: the AVX walks where the processor has them) or with the four-lane
    /// kernels whatever the processor (`plain == true`).
    fn list_answers(
        mesh: &TriMesh,
        packs: &TrianglePacks,
        ids: &[u32],
        range: (usize, usize),
        ray: &Ray,
        plain: bool,
    ) -> (Hit, bool) {
        #[derive(Clone, Copy)]
        struct List<'a, const ANY: bool> {
            mesh: &'a TriMesh,
            packs: &'a TrianglePacks,
            ids: &'a [u32],
            range: (usize, usize),
        }
        impl<const ANY: bool> TriangleLoop for List<'_, ANY> {
            type Output = Hit;
            // Inline, as the walks' `run` is: so that the AVX path's lane operations are inlined
            // into the function compiled with AVX (else they stay calls: slower, not wrong).
            #[inline(always)]
            fn run<T: TriangleTest>(self, test: T) -> Hit {
                let mut best = Hit::MISS;
                let mut mailbox = Mailbox::new();
                let refs = Refs {
                    ids: self.ids,
                    packs: self.packs,
                };
                let any = test_refs::<T, ANY>(
                    &test,
                    self.mesh,
                    refs,
                    self.range,
                    &mut best,
                    &mut mailbox,
                );
                any.unwrap_or(best)
            }
        }
        fn run<L: TriangleLoop<Output = Hit>>(
            mesh: &TriMesh,
            ray: &Ray,
            lp: L,
            plain: bool,
        ) -> Hit {
            if !plain {
                return run_query(mesh, Aabb::EMPTY, ray, None, lp);
            }
            PreparedRay::prepare(ray, &mesh.bounds())
                .map_or(Hit::MISS, |r| r.dispatch_plain(None, lp))
        }
        let closest = List::<false> {
            mesh,
            packs,
            ids,
            range,
        };
        let any = List::<true> {
            mesh,
            packs,
            ids,
            range,
        };
        (
            run(mesh, ray, closest, plain),
            run(mesh, ray, any, plain).is_hit(),
        )
    }

    /// The scalar test on every triangle, for `ray`.
    fn scalar_answer(mesh: &TriMesh, ray: &Ray) -> Hit {
        struct All<'a>(&'a TriMesh);
        impl TriangleLoop for All<'_> {
            type Output = Hit;
            fn run<T: TriangleTest>(self, test: T) -> Hit {
                test_all::<T, false>(&test, self.0)
            }
        }
        run_query(mesh, Aabb::EMPTY, ray, None, All(mesh))
    }

    /// The four-wide list test, packed (block-aligned lists) and indexed (gathered, unaligned
    /// lists), gives the scalar test's answer bit for bit on more than a million random and
    /// adversarial ray/triangle pairs: lists of 1 to 13 triangles around one ray, from the
    /// triangle test's generator (aimed at vertices and edges, just outside them, exact lines,
    /// grazing, degenerate, slivers, tiny to huge scales).
    #[test]
    fn list_test_equals_the_scalar_test() {
        let mut rng = SplitMix64::new(0x11575);
        let (mut pairs, mut hits) = (0usize, 0usize);
        let mut case = 0usize;
        while pairs < 1_050_000 {
            let (ray, first) = pair(&mut rng, case);
            let n = 1 + rng.below(13);
            let mut tris = alloc::vec![first];
            // The others: the same scale (`pair` cycles scales by case), aimed at by other rays.
            for k in 1..n {
                tris.push(pair(&mut rng, case + 8 * k).1);
            }
            case += 1;
            let vertices: alloc::vec::Vec<[f32; 3]> =
                tris.iter().flat_map(|t| t.map(|p| p.to_array())).collect();
            let indices: alloc::vec::Vec<[u32; 3]> = (0..n as u32)
                .map(|i| [3 * i, 3 * i + 1, 3 * i + 2])
                .collect();
            let Ok(mesh) = TriMesh::new(&vertices, &indices, &mut MemoryBudget::new(0)) else {
                continue;
            };
            let want = scalar_answer(&mesh, &ray);
            // Packed: the list from a block boundary, in reverse id order (lists need no order).
            let ids: alloc::vec::Vec<u32> = (0..n as u32).rev().collect();
            let packed = TrianglePacks::build(
                &mesh,
                &ids,
                TriangleLayout::Packed,
                &mut MemoryBudget::new(0),
            )
            .unwrap();
            // Indexed: the list at an offset that is not a multiple of four.
            let shift = 1 + rng.below(3);
            let mut shifted = alloc::vec![Hit::INVALID_ID; shift];
            shifted.extend(0..n as u32);
            let packed_lists = |plain| list_answers(&mesh, &packed, &ids, (0, n), &ray, plain);
            let indexed = TrianglePacks::default();
            let indexed_lists = |plain| {
                let range = (shift, shift + n);
                list_answers(&mesh, &indexed, &shifted, range, &ray, plain)
            };
            for (label, (closest, any)) in [
                ("packed", packed_lists(false)),
                ("packed, four lanes", packed_lists(true)),
                ("indexed", indexed_lists(false)),
                ("indexed, four lanes", indexed_lists(true)),
            ] {
                assert!(
                    closest.same_bits(&want) && any == want.is_hit(),
                    "{label}: ray {ray:?} triangles {tris:?}: got {closest:?} (any {any}), want {want:?}"
                );
            }
            pairs += n;
            hits += usize::from(want.is_hit());
        }
        assert!(hits > 50_000, "only {hits} lists were hit");
    }
}
