//! The 8-byte kd-tree node.

/// One kd-tree node in 8 bytes.
///
/// - interior: `a` = the split position's f32 bits; `b` = `above << 2 | axis` (axis 0..=2), where the
///   child below the plane is the next node in the array (depth-first order) and `above` is the index
///   of the child above it;
/// - leaf: `b` = `count << 2 | 3`; `a` = the offset of the leaf's `count` triangles in the tree's
///   primitive array.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct KdNode {
    a: u32,
    b: u32,
}

const _: () = assert!(core::mem::size_of::<KdNode>() == 8);

/// The largest child index or leaf count a node can hold (30 bits).
pub const MAX_NODE_FIELD: u32 = (1 << 30) - 1;

impl KdNode {
    /// An interior node splitting `axis` at `split`, whose upper child is node `above`
    /// (`above <= MAX_NODE_FIELD`, checked by the builder).
    #[inline]
    pub fn interior(axis: usize, split: f32, above: u32) -> KdNode {
        KdNode {
            a: split.to_bits(),
            b: (above << 2) | (axis as u32 & 3),
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

    /// The upper child of an interior node.
    #[inline(always)]
    pub fn above(self) -> u32 {
        self.b >> 2
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
        let n = KdNode::interior(2, -3.5, MAX_NODE_FIELD);
        assert!(!n.is_leaf());
        assert_eq!((n.axis(), n.split(), n.above()), (2, -3.5, MAX_NODE_FIELD));
        let l = KdNode::leaf(MAX_NODE_FIELD, 77);
        assert!(l.is_leaf());
        assert_eq!((l.count(), l.offset()), (MAX_NODE_FIELD, 77));
        assert!(KdNode::leaf(0, 0).is_leaf());
    }
}
