//! The uniform grid: a linear-time build (count, prefix sum, fill) into two flat arrays, and a 3D-DDA
//! traversal that visits cells front to back.

use alloc::vec::Vec;
use glam::{DVec3, Vec3};

use crate::accel::{Aabb, RayQuery};
use crate::budget::{bytes_of, MemoryBudget};
use crate::error::BuildError;
use crate::math;
use crate::mesh::TriMesh;
use crate::ray::{Hit, PreparedRay, Ray, NEAR_MISS_TOLERANCE};

/// The grid's knobs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GridParams {
    /// Cells per non-degenerate triangle (λ): the grid has about λ·N cells, split between the axes in
    /// proportion to the box's shape. Must be finite and positive.
    pub density: f32,
    /// Insert a triangle only into the cells it really overlaps (separating-axis test) when its bounds
    /// span more than one cell in two or more axes; otherwise every cell of its bounds.
    pub exact_overlap: bool,
}

impl GridParams {
    /// The default: λ = 2 with exact overlap, a good all-round setting on the bundled scenes
    /// (docs/design.md records the measurement).
    pub const DEFAULT: GridParams = GridParams {
        density: 2.0,
        exact_overlap: true,
    };
    /// Fewer cells (λ = 0.5): less memory and a faster build, slower rays.
    pub const COARSE: GridParams = GridParams {
        density: 0.5,
        exact_overlap: true,
    };
    /// More cells (λ = 8): faster rays on clustered scenes, more memory.
    pub const FINE: GridParams = GridParams {
        density: 8.0,
        exact_overlap: true,
    };
}

impl Default for GridParams {
    fn default() -> Self {
        GridParams::DEFAULT
    }
}

/// A uniform grid over a [`TriMesh`].
///
/// # Guarantees
/// - every non-degenerate triangle is listed in every cell it overlaps, where "overlaps" is tested
///   against the cell enlarged by a margin (1/128 of a cell plus twice the triangle test's near-miss
///   allowance), so neither rounding in the traversal nor the allowance can skip a triangle that the
///   shared test would hit, for ray origins up to ~1000 box diagonals away;
/// - each cell's list is sorted by primitive id;
/// - `offsets.len() == cells + 1`, `offsets` is non-decreasing and ends at `refs.len()`.
#[derive(Debug)]
pub struct UniformGrid {
    bounds: Aabb,
    res: [u32; 3],
    cell_size: Vec3,
    inv_cell_size: Vec3,
    margin: Vec3,
    offsets: Vec<u32>,
    refs: Vec<u32>,
}

/// What one query did, for the selector's deterministic cost model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct GridWork {
    /// Cells visited.
    pub cells: u32,
    /// Triangle tests run.
    pub tests: u32,
}

impl UniformGrid {
    /// Builds the grid over `mesh`, charging its arrays to `budget`. Time and memory are linear in
    /// the number of triangles plus cells plus references.
    pub fn build(
        mesh: &TriMesh,
        params: &GridParams,
        budget: &mut MemoryBudget,
    ) -> Result<UniformGrid, BuildError> {
        if !(params.density.is_finite() && params.density > 0.0) {
            return Err(BuildError::InvalidArgument {
                what: "grid density must be finite and positive",
            });
        }
        let live = mesh.len() - mesh.degenerate_count();
        let tight = mesh.bounds();
        if live == 0 || tight.is_empty() {
            return Ok(UniformGrid {
                bounds: Aabb::EMPTY,
                res: [0; 3],
                cell_size: Vec3::ZERO,
                inv_cell_size: Vec3::ZERO,
                margin: Vec3::ZERO,
                offsets: Vec::new(),
                refs: Vec::new(),
            });
        }
        let (bounds, res) = layout(tight, live, params.density)?;
        let cells = res[0] as usize * res[1] as usize * res[2] as usize;
        let resf = Vec3::new(res[0] as f32, res[1] as f32, res[2] as f32);
        let cell_size = (bounds.max - bounds.min) / resf;
        let inv_cell_size = resf / (bounds.max - bounds.min);
        let abs_scale = bounds.min.abs().max(bounds.max.abs()).max_element();
        let margin = cell_size * (1.0 / 128.0) + Vec3::splat(abs_scale * 2.0 * NEAR_MISS_TOLERANCE);
        let mut grid = UniformGrid {
            bounds,
            res,
            cell_size,
            inv_cell_size,
            margin,
            offsets: Vec::new(),
            refs: Vec::new(),
        };

        let geometry = grid.geometry();
        let mut counts = budget.filled(cells + 1, 0u32, "grid cell offsets")?;
        let mut overflow = false;
        for (prim, tri) in mesh.triangles().iter().enumerate() {
            if mesh.is_degenerate(prim as u32) {
                continue;
            }
            grid_cells(&geometry, tri, params.exact_overlap, |c| {
                let n = &mut counts[c];
                *n = n.wrapping_add(1);
                overflow |= *n == 0;
            });
        }
        // Inclusive prefix sums: counts[c] becomes the end of cell c's list.
        let mut total: u64 = 0;
        for n in counts.iter_mut().take(cells) {
            total += u64::from(*n);
            if overflow || total > u64::from(u32::MAX) {
                budget.free(counts);
                return Err(BuildError::CapacityExceeded {
                    what: "grid references",
                });
            }
            *n = total as u32;
        }
        counts[cells] = total as u32;
        let refs = match budget.filled(total as usize, 0u32, "grid references") {
            Ok(r) => r,
            Err(e) => {
                budget.free(counts);
                return Err(e);
            }
        };
        grid.refs = refs;
        // Filling backwards leaves each list sorted by primitive id and counts[c] at its start.
        for (prim, tri) in mesh.triangles().iter().enumerate().rev() {
            if mesh.is_degenerate(prim as u32) {
                continue;
            }
            let refs = &mut grid.refs;
            grid_cells(&geometry, tri, params.exact_overlap, |c| {
                counts[c] -= 1;
                refs[counts[c] as usize] = prim as u32;
            });
        }
        grid.offsets = counts;
        Ok(grid)
    }

    /// Cells per axis (zero for an empty scene).
    pub fn resolution(&self) -> [u32; 3] {
        self.res
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.offsets.len().saturating_sub(1)
    }

    /// Number of triangle references over all cells.
    pub fn reference_count(&self) -> usize {
        self.refs.len()
    }

    /// Bytes the grid holds.
    pub fn memory_bytes(&self) -> usize {
        bytes_of(&self.offsets) + bytes_of(&self.refs)
    }

    /// Gives the grid's bytes back to the budget it was charged to and drops it.
    pub fn release(self, budget: &mut MemoryBudget) {
        budget.free(self.offsets);
        budget.free(self.refs);
    }

    /// The closest hit, also counting the work done.
    pub fn intersect_counted(&self, mesh: &TriMesh, ray: &Ray, work: &mut GridWork) -> Hit {
        self.closest::<true>(mesh, ray, work)
    }

    fn geometry(&self) -> Geometry {
        Geometry {
            min: self.bounds.min,
            res: self.res,
            cell_size: self.cell_size,
            inv: self.inv_cell_size,
            margin: self.margin,
        }
    }

    #[inline(always)]
    fn cell_prims(&self, cell: usize) -> &[u32] {
        let lo = self.offsets.get(cell).copied().unwrap_or(0) as usize;
        let hi = self.offsets.get(cell + 1).copied().unwrap_or(0) as usize;
        self.refs.get(lo..hi).unwrap_or(&[])
    }

    #[inline(always)]
    fn closest<const COUNT: bool>(&self, mesh: &TriMesh, ray: &Ray, work: &mut GridWork) -> Hit {
        let Some(r) = PreparedRay::new(ray) else {
            return Hit::MISS;
        };
        let mut best = Hit::MISS;
        self.walk(&r, |cell, t_exit| {
            let prims = self.cell_prims(cell);
            if COUNT {
                work.cells += 1;
                work.tests += prims.len() as u32;
            }
            for &prim in prims {
                let Some(t) = mesh.triangle(prim) else {
                    continue;
                };
                if let Some((t, u, v)) = r.intersect_triangle(t[0], t[1], t[2]) {
                    let h = Hit { t, u, v, prim };
                    if h.beats(&best) {
                        best = h;
                    }
                }
            }
            // Any triangle not yet tested lies beyond this cell (by the insertion margin), so a hit
            // inside the cell cannot be beaten.
            best.t <= t_exit
        });
        best
    }

    /// Visits the cells the ray passes through inside `[tmin, tmax]`, front to back, until `visit`
    /// returns true. `visit` gets the cell index and the ray parameter where the ray leaves the cell.
    #[inline(always)]
    fn walk(&self, r: &PreparedRay, mut visit: impl FnMut(usize, f32) -> bool) {
        if self.offsets.is_empty() {
            return;
        }
        let (o, d) = (r.org, r.dir);
        let mut t0 = r.tmin;
        let mut t1 = r.tmax;
        let mut inv = [0.0f32; 3];
        let mut moving = [false; 3];
        for a in 0..3 {
            let ia = 1.0 / d[a];
            if ia.is_finite() {
                inv[a] = ia;
                moving[a] = true;
                let ta = (self.bounds.min[a] - o[a]) * ia;
                let tb = (self.bounds.max[a] - o[a]) * ia;
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            } else if o[a] < self.bounds.min[a] || o[a] > self.bounds.max[a] {
                return;
            }
        }
        if !(t0 <= t1) {
            return;
        }
        let t_start = t0.clamp(-f32::MAX, f32::MAX);
        let mut cell = [0i64; 3];
        let mut step = [0i64; 3];
        let mut t_next = [f32::INFINITY; 3];
        for a in 0..3 {
            let p = o[a] + t_start * d[a];
            let c = math::floor((p - self.bounds.min[a]) * self.inv_cell_size[a]);
            let last = self.res[a] as i64 - 1;
            cell[a] = if c.is_nan() {
                0
            } else {
                (c.clamp(-1.0, last as f32 + 1.0) as i64).clamp(0, last)
            };
            if moving[a] {
                step[a] = if d[a] > 0.0 { 1 } else { -1 };
                t_next[a] = self.boundary_t(a, cell[a] + i64::from(d[a] > 0.0), o[a], inv[a]);
            }
        }
        let (rx, rxy) = (
            self.res[0] as usize,
            self.res[0] as usize * self.res[1] as usize,
        );
        loop {
            let index = cell[0] as usize + cell[1] as usize * rx + cell[2] as usize * rxy;
            let axis = if t_next[0] <= t_next[1] && t_next[0] <= t_next[2] {
                0
            } else if t_next[1] <= t_next[2] {
                1
            } else {
                2
            };
            let t_exit = t_next[axis].min(t1);
            if visit(index, t_exit) || t_next[axis] > t1 {
                return;
            }
            cell[axis] += step[axis];
            if cell[axis] < 0 || cell[axis] >= self.res[axis] as i64 {
                return;
            }
            t_next[axis] = self.boundary_t(
                axis,
                cell[axis] + i64::from(step[axis] > 0),
                o[axis],
                inv[axis],
            );
        }
    }

    /// Ray parameter at the plane between cells `k - 1` and `k` on `axis`, computed from the plane's
    /// position each time (no accumulated error).
    #[inline(always)]
    fn boundary_t(&self, axis: usize, k: i64, o: f32, inv: f32) -> f32 {
        let x = self.bounds.min[axis] + k as f32 * self.cell_size[axis];
        (x - o) * inv
    }
}

impl RayQuery for UniformGrid {
    fn bounds(&self) -> Aabb {
        self.bounds
    }

    fn intersect(&self, mesh: &TriMesh, ray: &Ray) -> Hit {
        self.closest::<false>(mesh, ray, &mut GridWork::default())
    }

    fn occluded(&self, mesh: &TriMesh, ray: &Ray) -> bool {
        let Some(r) = PreparedRay::new(ray) else {
            return false;
        };
        let mut hit = false;
        self.walk(&r, |cell, _| {
            hit = self.cell_prims(cell).iter().any(|&prim| {
                mesh.triangle(prim)
                    .is_some_and(|t| r.intersect_triangle(t[0], t[1], t[2]).is_some())
            });
            hit
        });
        hit
    }
}

/// What the build needs of the grid's shape, copied out so the fill pass can borrow `refs` mutably.
struct Geometry {
    min: Vec3,
    res: [u32; 3],
    cell_size: Vec3,
    inv: Vec3,
    margin: Vec3,
}

/// The padded box and cells per axis for `live` triangles in `tight` at density `lambda`.
fn layout(tight: Aabb, live: usize, lambda: f32) -> Result<(Aabb, [u32; 3]), BuildError> {
    let ext = tight.extent();
    let max_ext = ext.max_element();
    let abs_scale = tight.min.abs().max(tight.max.abs()).max_element();
    // Pad so that triangles on the box faces lie strictly inside and flat scenes get a thin slab.
    // The pad also covers the triangle test's near-miss allowance, so a ray that grazes a triangle on
    // the box's face is not clipped away.
    let pad = max_ext * (1.0 / 1024.0) + abs_scale * 2.0 * NEAR_MISS_TOLERANCE + f32::MIN_POSITIVE;
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

/// Calls `visit` with the index of every cell triangle `tri` overlaps (with the margin).
fn grid_cells(g: &Geometry, tri: &[Vec3; 3], exact: bool, mut visit: impl FnMut(usize)) {
    let bb = Aabb::of_triangle(tri);
    let lo = cell_range(g, bb.min - g.margin);
    let hi = cell_range(g, bb.max + g.margin);
    let (rx, rxy) = (g.res[0] as usize, g.res[0] as usize * g.res[1] as usize);
    let spans = (0..3).filter(|&a| hi[a] > lo[a]).count();
    let test = exact && spans >= 2;
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                if test {
                    let cmin = g.min + Vec3::new(x as f32, y as f32, z as f32) * g.cell_size;
                    let center = (cmin + 0.5 * g.cell_size).as_dvec3();
                    let half = (0.5 * g.cell_size + g.margin).as_dvec3();
                    if !triangle_overlaps_box(tri, center, half) {
                        continue;
                    }
                }
                visit(x as usize + y as usize * rx + z as usize * rxy);
            }
        }
    }
}

fn cell_range(g: &Geometry, p: Vec3) -> [u32; 3] {
    let mut c = [0u32; 3];
    for a in 0..3 {
        let f = math::floor((p[a] - g.min[a]) * g.inv[a]);
        c[a] = f.clamp(0.0, (g.res[a] - 1) as f32) as u32;
    }
    c
}

/// Separating-axis test of a triangle against a box (center, half extents), in f64 so that the only
/// tolerance that matters is the margin already added to the box.
fn triangle_overlaps_box(tri: &[Vec3; 3], center: DVec3, half: DVec3) -> bool {
    let v = [
        tri[0].as_dvec3() - center,
        tri[1].as_dvec3() - center,
        tri[2].as_dvec3() - center,
    ];
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    // The nine edge × box-axis directions.
    for edge in &e {
        for axis in [DVec3::X, DVec3::Y, DVec3::Z] {
            let n = axis.cross(*edge);
            if separates(n, &v, half) {
                return false;
            }
        }
    }
    // The triangle's plane (box axes were handled by the bounds).
    !separates(e[0].cross(e[1]), &v, half)
}

fn separates(n: DVec3, v: &[DVec3; 3], half: DVec3) -> bool {
    let p0 = n.dot(v[0]);
    let p1 = n.dot(v[1]);
    let p2 = n.dot(v[2]);
    let r = half.dot(n.abs());
    p0.min(p1).min(p2) > r || p0.max(p1).max(p2) < -r
}
