//! The 8-byte kd-tree node.

/// One kd-tree node in 8 bytes.
///
/// - interior: `a` = the split position's f32 bits; `b` = `children << 4 | empty_above << 3 |
///   empty_below << 2 | axis` (axis 0..=2), where the children are the nodes `children` (below the
///   plane, an even index) and `children + 1` (above it), side by side so that a ray picks its near
///   child by adding its direction's sign and the far one as `near ^ 1`, and the two flags say that
///   a child is a leaf without triangles, so the traversal need not visit it;
/// - leaf: `b` = `count << 2 | 3`; `a` = the offset of the leaf's `count` triangles in the tree's
///   primitive array.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KdNode {
    a: u32,
    b: u32,
}

const _: () = assert!(core::mem::size_of::<KdNode>() == 8);

/// The bit of an interior node's [`KdNode::bits`] that flags its lower child as an empty leaf.
pub const EMPTY_BELOW: u32 = 1 << 2;

/// The bit of an interior node's [`KdNode::bits`] that flags its upper child as an empty leaf.
pub const EMPTY_ABOVE: u32 = 1 << 3;

/// The largest leaf count a node can hold (30 bits).
pub const MAX_NODE_FIELD: u32 = (1 << 30) - 1;

/// The largest index of a node's first child (28 bits: the interior node also holds two flags).
pub const MAX_CHILD_INDEX: u32 = (1 << 28) - 2;

impl KdNode {
    /// An interior node splitting `axis` at `split`, whose children are nodes `children` (below)
    /// and `children + 1` (above) (`children <= MAX_CHILD_INDEX`, checked by the builder); `empty`
    /// says which children are leaves without triangles (lower, upper).
    #[inline]
    pub fn interior(axis: usize, split: f32, children: u32, empty: (bool, bool)) -> KdNode {
        KdNode {
            a: split.to_bits(),
            b: (children << 4)
                | if empty.1 { EMPTY_ABOVE } else { 0 }
                | if empty.0 { EMPTY_BELOW } else { 0 }
                | (axis as u32 & 3),
        }
    }

    /// A leaf of `count` triangles at `offset` in the primitive array (`count <= MAX_NODE_FIELD`,
    /// checked by the builder).
    #[inline]
    pub fn leaf(count: u32, offset: u32) -> KdNode {
        KdNode {
            a: offset,
            b: (count << 2) | 3,
        }
    }

    /// True for a leaf.
    #[inline(always)]
    pub fn is_leaf(self) -> bool {
        self.b & 3 == 3
    }

    /// The split axis of an interior node.
    #[inline(always)]
    pub fn axis(self) -> usize {
        (self.b & 3) as usize
    }

    /// The split position of an interior node.
    #[inline(always)]
    pub fn split(self) -> f32 {
        f32::from_bits(self.a)
    }

    /// The lower child of an interior node (the upper one follows it).
    #[inline(always)]
    pub fn children(self) -> u32 {
        self.b >> 4
    }

    /// The second word: for an interior node, its child index, axis and the [`EMPTY_BELOW`] and
    /// [`EMPTY_ABOVE`] flags.
    #[inline(always)]
    pub fn bits(self) -> u32 {
        self.b
    }

    /// The triangle count of a leaf.
    #[inline(always)]
    pub fn count(self) -> u32 {
        self.b >> 2
    }

    /// The offset of a leaf's triangles in the primitive array.
    #[inline(always)]
    pub fn offset(self) -> u32 {
        self.a
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fields_round_trip() {
        let n = KdNode::interior(2, -3.5, MAX_CHILD_INDEX, (false, true));
        assert!(!n.is_leaf());
        assert_eq!(
            (
                n.axis(),
                n.split(),
                n.children(),
                n.bits() & (EMPTY_BELOW | EMPTY_ABOVE)
            ),
            (2, -3.5, MAX_CHILD_INDEX, EMPTY_ABOVE)
        );
        let m = KdNode::interior(0, 1.0, 7, (true, false));
        assert_eq!(
            (
                m.children(),
                m.bits() & (EMPTY_BELOW | EMPTY_ABOVE),
                m.axis()
            ),
            (7, EMPTY_BELOW, 0)
        );
        let l = KdNode::leaf(MAX_NODE_FIELD, 77);
        assert!(l.is_leaf());
        assert_eq!((l.count(), l.offset()), (MAX_NODE_FIELD, 77));
        assert!(KdNode::leaf(0, 0).is_leaf());
    }
}
