//! The grid's shape: the padded box, the cells per axis, the insertion margin, and how far from the
//! box a ray origin may be for the walk's rounding to stay inside that margin.

use glam::Vec3;

use crate::error::BuildError;
use crate::math;
use crate::ray::Aabb;

/// Unit roundoff of f32 (2^-24), the unit of the walk's rounding errors.
pub(super) const U32: f32 = f32::EPSILON / 2.0;

/// Box, resolution and margin of a grid (all zero for an empty one).
///
/// Guarantees (non-empty): `cell_size[a] = (max − min)[a] / res[a]` in f32 (the planes the walk
/// computes, `min + k·cell_size`, are the ones tests recompute), `res[a] ≥ 1`, the product of `res`
/// is below `u32::MAX`, and every non-degenerate triangle lies inside `bounds` by at least the
/// padding of [`Shape::new`].
#[derive(Clone, Copy, Debug)]
pub(super) struct Shape {
    /// The padded box.
    pub bounds: Aabb,
    /// Cells per axis.
    pub res: [u32; 3],
    /// Cell side per axis.
    pub cell_size: Vec3,
    /// The insertion margin per axis: a triangle is listed in every cell whose box, enlarged by
    /// this on every side, it meets (docs/design.md, "Uniform grid").
    pub margin: Vec3,
    /// The largest distance (per axis, from the ray origin to the farthest point of the box) at
    /// which the margin covers the walk's rounding (docs/design.md).
    pub near_reach: f32,
    /// The smallest cell side: with `near_reach`, what decides how a far ray is walked.
    pub min_cell: f32,
}

impl Shape {
    /// The shape of a grid with no triangles.
    pub const EMPTY: Shape = Shape {
        bounds: Aabb::EMPTY,
        res: [0; 3],
        cell_size: Vec3::ZERO,
        margin: Vec3::ZERO,
        near_reach: 0.0,
        min_cell: 0.0,
    };

    /// The shape for `live` non-degenerate triangles with bounds `tight` (not empty) at density
    /// `lambda` (about `lambda · live` cells).
    pub fn new(tight: Aabb, live: usize, lambda: f32) -> Result<Shape, BuildError> {
        let (bounds, res) = layout(tight, live, lambda)?;
        let resf = Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        let cell_size = (bounds.max - bounds.min) / resf;
        let abs_scale = bounds.min.abs().max(bounds.max.abs()).max_element();
        let extent = (bounds.max - bounds.min).max_element();
        // The walk's rounding moves a cell boundary by at most 4u·(D + 2A) (D the origin's distance,
        // A the coordinates' magnitude); a margin of twice that covers it. 16u·A covers the A part,
        // 16u·extent lets every origin within two extents of the grid qualify, and 1/64 of a cell
        // extends that to 32768 cells.
        let margin = cell_size * (1.0 / 64.0) + Vec3::splat(16.0 * U32 * (abs_scale + extent));
        let near_reach = margin.min_element() / (8.0 * U32) - 2.0 * abs_scale;
        Ok(Shape {
            bounds,
            res,
            cell_size,
            margin,
            near_reach,
            min_cell: cell_size.min_element(),
        })
    }

    /// Number of cells.
    pub fn cells(&self) -> usize {
        self.res[0] as usize * self.res[1] as usize * self.res[2] as usize
    }
}

/// The padded box and cells per axis for `live` triangles in `tight` at density `lambda`.
fn layout(tight: Aabb, live: usize, lambda: f32) -> Result<(Aabb, [u32; 3]), BuildError> {
    let ext = tight.extent();
    let max_ext = ext.max_element();
    let abs_scale = tight.min.abs().max(tight.max.abs()).max_element();
    // Pad so that triangles on the box faces lie strictly inside, by more than the walk's rounding
    // at the box's faces (16 roundings of the coordinates) and the far walk's entry point (1/2048
    // of a cell), and flat scenes get a thin slab.
    let pad = max_ext * (1.0 / 1024.0) + abs_scale * (16.0 * U32) + f32::MIN_POSITIVE;
    let bounds = Aabb {
        min: tight.min - Vec3::splat(pad),
        max: tight.max + Vec3::splat(pad),
    };
    let target = (f64::from(lambda) * live as f64).max(1.0);
    // Axes too thin to split get one cell; the others share the target in proportion to their extent.
    let e = [f64::from(ext.x), f64::from(ext.y), f64::from(ext.z)];
    let mut split = [true; 3];
    for (a, s) in split.iter_mut().enumerate() {
        *s = e[a] > f64::from(max_ext) * 1e-6;
    }
    let mut res = [1u32; 3];
    for _ in 0..3 {
        let dims = split.iter().filter(|&&s| s).count();
        if dims == 0 {
            break;
        }
        let volume: f64 = (0..3).filter(|&a| split[a]).map(|a| e[a]).product();
        let k = match dims {
            1 => target / volume,
            2 => math::sqrt64(target / volume),
            _ => math::cbrt(target / volume),
        };
        let mut changed = false;
        for a in 0..3 {
            if split[a] {
                let r = e[a] * k;
                if r < 1.0 {
                    split[a] = false;
                    changed = true;
                }
                res[a] = math::floor64(r + 0.5).clamp(1.0, target.min(f64::from(u32::MAX))) as u32;
            } else {
                res[a] = 1;
            }
        }
        if !changed {
            break;
        }
    }
    let cells = u64::from(res[0]) * u64::from(res[1]) * u64::from(res[2]);
    if cells >= u64::from(u32::MAX) || cells as u128 + 1 > usize::MAX as u128 {
        return Err(BuildError::CapacityExceeded { what: "grid cells" });
    }
    Ok((bounds, res))
}
