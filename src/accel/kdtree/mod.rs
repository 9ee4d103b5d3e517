//! The SAH kd-tree: an O(N log N) event-sweep build with perfect splits (build.rs), 8-byte nodes
//! (node.rs) and a stack-based front-to-back traversal (traverse.rs).

use alloc::vec::Vec;

use crate::accel::{run_clipped_query, Aabb, AcceptingQuery, RayQuery};
use crate::budget::{bytes_of, MemoryBudget};
use crate::error::BuildError;
use crate::mesh::TriMesh;
use crate::ray::{Hit, Ray};
use crate::triangle::packs::{TriangleLayout, TrianglePacks};
use crate::triangle::Accept;

mod build;
mod clip;
pub mod node;
mod traverse;

use node::KdNode;
use traverse::{Clip, Walk};

/// The deepest tree the builder makes; the traversal stack has room for it.
pub const MAX_DEPTH: u32 = 60;

/// The kd-tree's knobs. The costs are in units of one traversal step; the calibration supplies
/// measured ones later.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KdTreeParams {
    /// Cost of visiting an interior node (the SAH's `C_t`). Finite, positive.
    pub traversal_cost: f32,
    /// Cost of one triangle test (the SAH's `C_i`). Finite, positive.
    pub intersection_cost: f32,
    /// Fraction of a split's cost forgiven when one child is empty (in `[0, 1)`): cutting off empty
    /// space pays beyond what the SAH counts, because rays leave such nodes early.
    pub empty_bonus: f32,
    /// Depth limit; 0 = automatic, `8 + 1.3·log2 N` (a safety net: the SAH stops first almost
    /// always). At most [`MAX_DEPTH`].
    pub max_depth: u32,
    /// Nodes with at most this many triangles become leaves without a split search.
    pub max_leaf_prims: u32,
    /// Bound on leaf references per triangle from clipped straddlers: once the tree would hold more,
    /// nodes stop splitting. At least 1.
    pub max_references_per_triangle: f32,
    /// Nodes of at most this many triangles choose their split by the exact SAH over every
    /// candidate plane; larger ones by min-max binning (32 bins per axis): the build-time and
    /// tree-quality knob.
    pub exact_below: u32,
    /// How the leaves' triangles are stored for the test (packed copies or ids only).
    pub layout: TriangleLayout,
}

impl KdTreeParams {
    /// The default: a block test priced at 0.35 of a node step (`C_t = 1`, `C_i = 0.35` per block
    /// of four; 0.5 until stop 34: once the AVX filter tested lists two blocks at a time (stop 33),
    /// bigger leaves cost less, and over the evaluation's 29 scenes below a million triangles
    /// `C_i = 0.35` built in 0.87× the time of 0.5 with the same time per ray (0.989–0.994 in the
    /// geometric mean, six alternated runs; tetra-10k 0.99–1.02, hair-50k 0.95);
    /// docs/performance.md, "Stop 34") and empty-space bonus 0.125 (stop 25: against 0.5, 0.94×
    /// the time per ray in the
    /// geometric mean over 29 scenes in two runs, 0.80–1.02× per scene, the build unchanged;
    /// a node step costs about ten triangle tests in time, so fewer cuts of empty space pay;
    /// docs/performance.md, "Stop 25"); min-max binning at every node (stop 20: against the exact
    /// split for nodes of at most 16 triangles, 10–32 % fewer build instructions on bunny, sibenik,
    /// gears, hair, slivers, soup and stadium, and the same instructions per ray within 0.02 %
    /// but sibenik's +1.0 %; callgrind; binning everywhere is 2–4 % more instructions per ray
    /// than sweeping exactly up to 1 024, `HIGH`, for 1.0–2.1× less build); a reference share of 64
    /// per triangle, which the SAH's own termination
    /// leaves unused on well-shaped scenes. The costs were chosen by time, not by instructions: a
    /// node step costs more than its ~33 instructions (the nodes of a deep tree miss the cache),
    /// and over the evaluation's scenes (29, one thread, timed per ray and per build against
    /// `C_i = 1`, bonus 0.8, in two runs at stop 19, with bonus 0.5) `C_i = 0.5` traced 4–5 % faster and built 16–17 %
    /// faster (geometric means; hair 1.7× faster per ray, soup 1.18×; a few small scenes up to
    /// 9 % slower); docs/performance.md, "kd-tree costs by time".
    pub const DEFAULT: KdTreeParams = KdTreeParams {
        traversal_cost: 1.0,
        intersection_cost: 0.35,
        empty_bonus: 0.125,
        max_depth: 0,
        max_leaf_prims: 1,
        max_references_per_triangle: 64.0,
        exact_below: 0,
        layout: TriangleLayout::Packed,
    };

    /// A faster build for few rays: tests priced at half the default's (`C_i = 0.175`), so
    /// shallower trees with bigger leaves (stop 34, against the default on 14 scenes: 0.78× its
    /// build time, 2–3 % slower per ray in the geometric mean, up to 7 % on sibenik and the
    /// Sierpinski tetrahedra; at stop 25, `C_i` 0.25 against 0.5: 0.75× and 1.7–2.3 %).
    pub const FAST: KdTreeParams = KdTreeParams {
        intersection_cost: 0.175,
        ..KdTreeParams::DEFAULT
    };

    /// A better tree for many rays: the exact sweep up to 1 024 triangles (stop 34, against the
    /// default on 29 scenes: 2.73× its build time (1.83–4.10 over 12 scenes), 0.977× the time per
    /// ray in the geometric mean (five rounds; 0.956 within a call, against the unchanged grid),
    /// 0.82–1.02 per scene; at stop 25, with `C_i` = 0.5, 2.7× for 0.977–0.984×; at stop 24, with
    /// bonus 0.5, 1.003× for 2.68×).
    pub const HIGH: KdTreeParams = KdTreeParams {
        exact_below: 1024,
        ..KdTreeParams::DEFAULT
    };

    fn validate(&self) -> Result<(), BuildError> {
        let positive = |x: f32| x.is_finite() && x > 0.0;
        if !(positive(self.traversal_cost) && positive(self.intersection_cost)) {
            return Err(BuildError::InvalidArgument {
                what: "kd-tree costs must be finite and positive",
            });
        }
        if !(self.empty_bonus >= 0.0 && self.empty_bonus < 1.0) {
            return Err(BuildError::InvalidArgument {
                what: "kd-tree empty bonus must be in [0, 1)",
            });
        }
        if !(self.max_references_per_triangle >= 1.0
            && self.max_references_per_triangle.is_finite())
        {
            return Err(BuildError::InvalidArgument {
                what: "kd-tree reference bound must be finite and at least 1",
            });
        }
        Ok(())
    }
}

impl Default for KdTreeParams {
    fn default() -> Self {
        KdTreeParams::DEFAULT
    }
}

/// What one query did, for the selector's deterministic cost model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct KdWork {
    /// Nodes visited (interior and leaves).
    pub nodes: u32,
    /// Leaves visited.
    pub leaves: u32,
    /// Triangle tests run.
    pub tests: u32,
}

/// A SAH kd-tree over a [`TriMesh`].
///
/// # Guarantees
/// - every point of every non-degenerate triangle lies in the closed box of a leaf that references
///   it (clipping is rounded outward; a triangle that only touches a split plane, or lies in it, is
///   sent to one side), so the traversal, which widens each ray's split intervals by its own
///   rounding, never skips a triangle the exact test would hit: answers are bit-identical to brute
///   force;
/// - every leaf's triangles are `prims[offset..offset + count]` (with the packed layout `offset` is a
///   multiple of 4 and the gaps hold `Hit::INVALID_ID`), and `packs` holds the triangles of `prims`
///   in its order (or nothing, for the indexed layout);
/// - depth ≤ [`MAX_DEPTH`], so the fixed traversal stack never overflows;
/// - nodes and references fit their 30- and 32-bit fields (`CapacityExceeded` otherwise).
#[derive(Debug)]
pub struct KdTree {
    bounds: Aabb,
    nodes: Vec<KdNode>,
    prims: Vec<u32>,
    packs: TrianglePacks,
    depth: u32,
    leaves: u32,
    references: usize,
    budget_leaves: usize,
    largest_budget_leaf: usize,
    work: u64,
}

impl KdTree {
    /// Builds the tree over `mesh`, charging its arrays (and the build's temporaries) to `budget`.
    /// Time O(N log N), memory O(N) plus the references of clipped straddlers.
    pub fn build(
        mesh: &TriMesh,
        params: &KdTreeParams,
        budget: &mut MemoryBudget,
    ) -> Result<KdTree, BuildError> {
        match Self::build_within(mesh, params, budget, u64::MAX) {
            Ok(Some(tree)) => Ok(tree),
            Err(e) => Err(e),
            // No build holds 2^64 items (each is 20 bytes of memory charged to the budget).
            Ok(None) => Err(BuildError::CapacityExceeded {
                what: "kd-tree build work",
            }),
        }
    }

    /// [`KdTree::build`], abandoned (`Ok(None)`, everything it took released) once its nodes have
    /// held more than `work_limit` items in all ([`KdTree::build_work`] of the finished tree): the
    /// selector's way of not paying in full for a tree that duplicates triangles without end.
    pub fn build_within(
        mesh: &TriMesh,
        params: &KdTreeParams,
        budget: &mut MemoryBudget,
        work_limit: u64,
    ) -> Result<Option<KdTree>, BuildError> {
        params.validate()?;
        let bounds = mesh.bounds();
        let live = mesh.len() - mesh.degenerate_count();
        let root = if live == 0 { Aabb::EMPTY } else { bounds };
        let built = if live == 0 {
            let mut nodes = budget.vec(1, "kd-tree nodes")?;
            nodes.push(KdNode::leaf(0, 0));
            build::Built {
                nodes,
                prims: Vec::new(),
                depth: 0,
                leaves: 1,
                references: 0,
                work: 0,
                budget_leaves: 0,
                largest_budget_leaf: 0,
            }
        } else {
            match build::build(mesh, params, root, budget, work_limit) {
                Ok(built) => built,
                Err(build::Stop::Failed(e)) => return Err(e),
                Err(build::Stop::OverWork) => return Ok(None),
            }
        };
        let packs = match TrianglePacks::build(mesh, &built.prims, params.layout, budget) {
            Ok(p) => p,
            Err(e) => {
                budget.free(built.nodes);
                budget.free(built.prims);
                return Err(e);
            }
        };
        Ok(Some(KdTree {
            bounds: root,
            nodes: built.nodes,
            prims: built.prims,
            packs,
            depth: built.depth,
            leaves: built.leaves,
            references: built.references,
            budget_leaves: built.budget_leaves,
            largest_budget_leaf: built.largest_budget_leaf,
            work: built.work,
        }))
    }

    /// Items the build's nodes held, summed over every node it split or made a leaf: the build's
    /// work, about `N·log2 N` times a small factor on well-shaped scenes and far more where
    /// straddlers multiply.
    pub fn build_work(&self) -> u64 {
        self.work
    }

    /// Nodes in the tree (interior and leaves; not the unused slot after the root that aligns the
    /// children pairs): `2·interior + 1`.
    pub fn node_count(&self) -> usize {
        // A tree of no live triangle is its root alone, without the unused slot.
        self.nodes.len().max(2) - 1
    }

    /// Leaves in the tree.
    pub fn leaf_count(&self) -> usize {
        self.leaves as usize
    }

    /// Depth of the deepest leaf (the root is at depth 0).
    pub fn depth(&self) -> u32 {
        self.depth
    }

    /// Triangle references held by the leaves (a straddling triangle counts once per leaf).
    pub fn reference_count(&self) -> usize {
        self.references
    }

    /// The most triangles in one leaf.
    pub fn largest_leaf(&self) -> usize {
        self.nodes
            .iter()
            .filter(|n| n.is_leaf())
            .map(|n| n.count() as usize)
            .max()
            .unwrap_or(0)
    }

    /// Leaves made because their subtree's share of the reference budget ran out, and the largest
    /// of them in triangles (`(0, 0)` when the budget never ran out).
    pub fn budget_leaves(&self) -> (usize, usize) {
        (self.budget_leaves, self.largest_budget_leaf)
    }

    /// Bytes the tree holds (nodes, references and their triangle packs).
    pub fn memory_bytes(&self) -> usize {
        bytes_of(&self.nodes) + bytes_of(&self.prims) + self.packs.memory_bytes()
    }

    /// Bytes of the triangle packs alone (zero for the indexed layout).
    pub fn pack_bytes(&self) -> usize {
        self.packs.memory_bytes()
    }

    /// Gives the tree's bytes back to the budget it was charged to and drops it.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.nodes);
        budget.free(self.prims);
        self.packs.release(budget);
    }

    /// The closest hit, also counting the work done.
    pub fn intersect_counted(&self, mesh: &TriMesh, ray: &Ray, work: &mut KdWork) -> Hit {
        self.query::<true, false>(mesh, ray, None, work)
    }

    /// Every query's walk: the ray clipped to the tree's box, then the walk (`COUNT` counts the
    /// work in `work`; `ANY` stops at the first hit).
    #[inline(always)]
    fn query<const COUNT: bool, const ANY: bool>(
        &self,
        mesh: &TriMesh,
        ray: &Ray,
        accept: Option<&dyn Accept>,
        work: &mut KdWork,
    ) -> Hit {
        run_clipped_query(mesh, self.bounds, ray, accept, |ray| {
            Some(Walk::<COUNT, ANY> {
                tree: self,
                mesh,
                work,
                clip: Clip::new(ray, &self.bounds)?,
            })
        })
    }
}

impl RayQuery for KdTree {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit {
        self.intersect_accepting(mesh, ray, None)
    }

    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool {
        self.occluded_accepting(mesh, ray, None)
    }
}

impl AcceptingQuery for KdTree {
    // Out of line, so plain queries share this one copy of the walks.
    #[inline(never)]
    fn intersect_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> Hit {
        self.query::<false, false>(mesh, ray, accept, &mut KdWork::default())
    }

    #[inline(never)]
    fn occluded_accepting(&self, mesh: &TriMesh, ray: &Ray, accept: Option<&dyn Accept>) -> bool {
        self.query::<false, true>(mesh, ray, accept, &mut KdWork::default())
            .is_hit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Interior nodes, leaves, the deepest leaf and the references, by walking the tree.
    fn walked(t: &KdTree) -> (usize, usize, u32, usize) {
        let mut stack = alloc::vec![(0u32, 0u32)];
        let (mut interior, mut leaves, mut depth, mut refs) = (0, 0, 0, 0);
        while let Some((i, d)) = stack.pop() {
            let n = t.nodes[i as usize];
            if n.is_leaf() {
                leaves += 1;
                depth = depth.max(d);
                refs += n.count() as usize;
            } else {
                interior += 1;
                stack.extend([(n.children(), d + 1), (n.children() + 1, d + 1)]);
            }
        }
        (interior, leaves, depth, refs)
    }

    /// What a tree says of itself is what it holds, also where the build retracted subtrees (whose
    /// depth `depth()` kept until a review noticed: gears of 50 triangles, one level deep, said 4)
    /// and for a mesh with no live triangle (`node_count` said 0 beside one leaf).
    #[test]
    fn a_tree_reports_the_shape_it_has() {
        for name in ["soup", "slivers", "gears", "hair", "sphere", "stadium"] {
            for n in [50, 700, 3000] {
                let data = crate::procedural::by_name(name, n).unwrap();
                let mesh =
                    TriMesh::from_source(&data.as_source(), &mut MemoryBudget::new(0)).unwrap();
                for params in [
                    KdTreeParams::DEFAULT,
                    KdTreeParams::HIGH,
                    KdTreeParams::FAST,
                ] {
                    let t = KdTree::build(&mesh, &params, &mut MemoryBudget::new(0)).unwrap();
                    let (interior, leaves, depth, refs) = walked(&t);
                    let what = alloc::format!("{name}-{n} {params:?}");
                    assert_eq!(depth, t.depth(), "{what}");
                    assert_eq!(2 * interior + 1, t.node_count(), "{what}");
                    assert_eq!(
                        (leaves, refs),
                        (t.leaf_count(), t.reference_count()),
                        "{what}"
                    );
                    let (budget_leaves, largest) = t.budget_leaves();
                    assert!(budget_leaves <= leaves && largest <= mesh.len(), "{what}");
                }
            }
        }
        let empty = crate::mesh::MeshData {
            vertices: alloc::vec![[0.0; 3]; 3],
            indices: alloc::vec![[0, 1, 2]],
        };
        let mesh = TriMesh::from_source(&empty.as_source(), &mut MemoryBudget::new(0)).unwrap();
        let t = KdTree::build(&mesh, &KdTreeParams::DEFAULT, &mut MemoryBudget::new(0)).unwrap();
        assert_eq!((t.node_count(), t.leaf_count(), t.depth()), (1, 1, 0));
    }
}
