//! Rays, hits and boxes: the plain values every structure and the triangle test share.

use glam::Vec3;

/// A ray `org + t·dir` restricted to `tmin ≤ t ≤ tmax`. `dir` need not be normalized.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    /// Origin.
    pub org: Vec3,
    /// Smallest accepted `t`.
    pub tmin: f32,
    /// Direction (any length except zero).
    pub dir: Vec3,
    /// Largest accepted `t`; may be `f32::INFINITY`.
    pub tmax: f32,
}

impl Ray {
    /// A ray over `[0, ∞]`.
    pub fn new(org: Vec3, dir: Vec3) -> Self {
        Ray {
            org,
            tmin: 0.0,
            dir,
            tmax: f32::INFINITY,
        }
    }

    /// A ray with an explicit `[tmin, tmax]` window.
    pub fn segment(org: Vec3, dir: Vec3, tmin: f32, tmax: f32) -> Self {
        Ray {
            org,
            tmin,
            dir,
            tmax,
        }
    }
}

/// The answer to a closest-hit query.
///
/// `u` and `v` are the barycentric weights of the triangle's second and third vertex. A miss is
/// [`Hit::MISS`]: `t = +∞`, `u = v = 0`, `prim = Hit::INVALID_ID`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Ray parameter of the hit.
    pub t: f32,
    /// Weight of the second vertex.
    pub u: f32,
    /// Weight of the third vertex.
    pub v: f32,
    /// Index of the triangle in the mesh.
    pub prim: u32,
}

impl Hit {
    /// The primitive id of a miss.
    pub const INVALID_ID: u32 = u32::MAX;
    /// What a query returns when nothing is hit.
    pub const MISS: Hit = Hit {
        t: f32::INFINITY,
        u: 0.0,
        v: 0.0,
        prim: Hit::INVALID_ID,
    };

    /// True when this is a hit.
    pub fn is_hit(&self) -> bool {
        self.prim != Hit::INVALID_ID
    }

    /// True when `self` should replace `best`: nearer, or as near with a lower primitive id.
    /// This is the tie rule every structure shares.
    #[inline(always)]
    pub fn beats(&self, best: &Hit) -> bool {
        self.t < best.t || (self.t == best.t && self.prim < best.prim)
    }

    /// Bit-level equality (distinguishes -0.0 from 0.0), the agreement tests' notion of "the same hit".
    pub fn same_bits(&self, other: &Hit) -> bool {
        self.t.to_bits() == other.t.to_bits()
            && self.u.to_bits() == other.u.to_bits()
            && self.v.to_bits() == other.v.to_bits()
            && self.prim == other.prim
    }
}

/// An axis-aligned box. [`Aabb::EMPTY`] has `min > max` and contains nothing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Lower corner.
    pub min: Vec3,
    /// Upper corner.
    pub max: Vec3,
}

impl Aabb {
    /// The box that contains nothing; growing it by a point gives that point.
    pub const EMPTY: Aabb = Aabb {
        min: Vec3::splat(f32::INFINITY),
        max: Vec3::splat(f32::NEG_INFINITY),
    };

    /// The smallest box holding `self` and `p`.
    #[inline]
    pub fn grow(self, p: Vec3) -> Aabb {
        Aabb {
            min: self.min.min(p),
            max: self.max.max(p),
        }
    }

    /// The smallest box holding both boxes.
    #[inline]
    pub fn union(self, other: Aabb) -> Aabb {
        Aabb {
            min: self.min.min(other.min),
            max: self.max.max(other.max),
        }
    }

    /// True when the box holds no point.
    pub fn is_empty(&self) -> bool {
        !(self.min.x <= self.max.x && self.min.y <= self.max.y && self.min.z <= self.max.z)
    }

    /// Edge lengths (zero for an empty box).
    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.max - self.min
        }
    }

    /// The bounds of a triangle.
    #[inline]
    pub fn of_triangle(t: &[Vec3; 3]) -> Aabb {
        // Four lanes at a time (the fourth unused): the same comparisons as `Vec3`'s `min`/`max`
        // lane by lane (`a < b ? a : b`), in a third of the instructions.
        let [a, b, c] = t.map(glam::Vec3A::from);
        Aabb {
            min: a.min(b).min(c).into(),
            max: a.max(b).max(c).into(),
        }
    }
}
