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
/// computes, `min + k·cell_size`, are the ones tests recompute), `1 ≤ res[a] ≤`
/// [`MAX_AXIS_CELLS`], the product of `res` is below `u32::MAX`, and every non-degenerate
/// triangle lies inside `bounds` by at least the padding of [`Shape::new`].
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
        let mut margin = cell_size * (1.0 / 64.0) + Vec3::splat(16.0 * U32 * (abs_scale + extent));
        if !margin.is_finite() && cell_size.is_finite() {
            // `abs_scale + extent` overflowed f32 (a scene reaching ±1e38): the same sum in f64.
            // An infinite margin put every triangle's footprint over the whole grid, where the
            // exact overlap's arithmetic then refused every cell (a fuzzing helper's finding).
            let wide = 16.0 * f64::from(U32) * (f64::from(abs_scale) + f64::from(extent));
            margin = cell_size
                .to_array()
                .map(|c| (f64::from(c) / 64.0 + wide) as f32)
                .into();
        }
        let mut near_reach = margin.min_element() / (8.0 * U32) - 2.0 * abs_scale;
        if !near_reach.is_finite() {
            // Overflowed (a margin above ~2^-21 of f32::MAX, a scene reaching ±1e38): the same in
            // f64, rounded down to f32 and at most f32::MAX, so an origin whose own f32 reach
            // overflows is walked as a far one, never claimed to be covered by the margin.
            let exact = f64::from(margin.min_element()) / (8.0 * f64::from(U32))
                - 2.0 * f64::from(abs_scale);
            // At least 0: the margin is at least 2^-20 of the sum that overflowed, so its 2^21
            // times is at least 2A.
            let capped = exact.clamp(0.0, f64::from(f32::MAX));
            let rounded = capped as f32;
            near_reach = if f64::from(rounded) > capped {
                // Positive (above `capped ≥ 0`): the next f32 below is one step of its bits.
                f32::from_bits(rounded.to_bits() - 1)
            } else {
                rounded
            };
        }
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

/// The narrowest cell a grid makes (2^-100): a scene far smaller than that across gets fewer,
/// wider cells. Below about 2^-128 the inverse of a cell's width overflows f32 and the insertion
/// listed every triangle in the last cell only, and a subnormal width leaves the planes
/// `min + k·size` with a fraction of f32's precision (a fuzzing helper's finding: a scene 1e-37
/// across at a high density lost its hits). The margin of 2^26 above 2^-126 keeps products of a
/// cell's units with the margins and slacks normal too.
const MIN_CELL: f64 = 7.888_609_052_210_118e-31;

/// The most cells on one axis (2^30): the insertion clamps f32 cell coordinates to this before it
/// truncates them to integers (`voxel::Cells`), so no axis may have a cell past it. (A grid with
/// more cells on an axis listed every triangle past cell 2^30 in that cell alone, where the walk
/// never looked: a review's line of 4 000 triangles at λ = 2.75·10⁵, 1.1·10⁹ cells on x.)
pub(super) const MAX_AXIS_CELLS: u32 = 1 << 30;

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
                res[a] =
                    math::floor64(r + 0.5).clamp(1.0, target.min(f64::from(MAX_AXIS_CELLS))) as u32;
            } else {
                res[a] = 1;
            }
        }
        if !changed {
            break;
        }
    }
    // No cell narrower than MIN_CELL: the insertion's f32 cell units (`1/cell_size` and what it
    // multiplies) must stay in f32's normal range.
    let padded = bounds.max - bounds.min;
    for (a, r) in res.iter_mut().enumerate() {
        let most = math::floor64(f64::from(padded[a]) / MIN_CELL).max(1.0);
        if f64::from(*r) > most {
            *r = most as u32;
        }
    }
    let cells = u64::from(res[0]) * u64::from(res[1]) * u64::from(res[2]);
    if cells >= u64::from(u32::MAX) || cells as u128 + 1 > usize::MAX as u128 {
        return Err(BuildError::CapacityExceeded { what: "grid cells" });
    }
    Ok((bounds, res))
}
