//! Which cells a triangle is listed in: every cell whose box, enlarged by the margin, the triangle
//! meets — a conservative voxelization, found by ranges of cells rather than by testing cells.
//!
//! The separating-axis theorem for a triangle and a box has 13 axes: the box's three (the
//! triangle's bounds settle them: the footprint), the triangle's normal (the plane test), and the
//! nine products of an edge with a box axis. The product of edge `e` with axis `x` is the normal of
//! `e` projected onto the yz plane, so those nine axes are exactly the edge normals of the
//! triangle's three axis-plane projections: a cell overlaps when its footprint, the plane, and the
//! three projections (2D triangle against the cell's rectangle) all say so. Each of these
//! conditions is a pair of linear inequalities in the cell's centre, so for a fixed row (or column)
//! of cells it is an interval of the remaining coordinate: rows of the projection onto the plane
//! most facing the triangle give runs of columns, and each column a run of cells along the third
//! axis — the overlapped cells, with work proportional to them plus the rows. Footprints of up to
//! four cells an axis are cheaper tested cell by cell, four cells at a time, as bit masks; thin
//! triangles with larger footprints slab by slab ([`slabs`]).
//!
//! The footprint is computed in f32 with a pad that covers its rounding, the row inequalities in
//! f64 cell units (`(p − min) / size`), the masks (2×2×2 or 4×4×4 cells) and the slabs in f32 cell
//! units from the footprint's corner, all against cells enlarged by the margin and then by a
//! relative 2^-10, far above the rounding of these few operations (docs/design.md bounds it), so no
//! cell the exact test would accept is dropped.

use glam::{Vec3, Vec3A, Vec4};

use super::layout::{Shape, MAX_AXIS_CELLS};
use slabs::slab_axis;

mod slabs;

/// Relative widening of the enlarged cell (in cell units), covering the rounding of the tests
/// (docs/design.md: below 2^-17 of a constraint's width in f64 for grids of up to 2^32 cells per
/// axis, below 12·2^-24 in the 2×2×2 f32 masks and 24·2^-24 in the 4×4×4 ones, below 1/1 000 of
/// a cell in the slabs).
const ROUNDING_SLACK: f64 = 1.0 + 1.0 / 1024.0;

/// What insertion needs of the grid's shape: the footprint in f32, the tests in f64 cell units.
#[derive(Clone, Copy, Debug)]
pub(super) struct Cells {
    res: [u32; 3],
    /// The flat index's step per axis.
    stride: [usize; 3],
    /// The flat index's offset of the cell `i, j, k` (bit `i + 2j + 4k`) from a footprint's corner.
    pub corner: [usize; 8],
    min32: Vec3A,
    /// `res / (max − min)` in f32.
    inv32: Vec3A,
    /// The margin plus a bound on the f32 footprint's rounding, in world units (see
    /// [`Cells::new`]).
    pad32: Vec3A,
    /// The largest cell coordinate the footprint's f32 values are clamped to before truncation:
    /// `res − 1` where every `res − 1` is at most 2^24 (exact in f32), else 2^30.
    cap32: Vec3A,
    /// Whether `cap32` is `res − 1` (so the truncated coordinates need no clamp of their own).
    exact_cap: bool,
    min: [f64; 3],
    /// 1 / cell size.
    inv: [f64; 3],
    /// Half an enlarged cell in cells, widened by the rounding slack.
    half: [f64; 3],
}

/// The cells of a triangle's bounds enlarged by the margin, `lo[a]..=hi[a]` per axis.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Footprint {
    pub lo: [u32; 3],
    pub hi: [u32; 3],
}

impl Footprint {
    /// Cells along `axis`.
    #[inline(always)]
    pub fn len(&self, axis: usize) -> u32 {
        self.hi[axis] - self.lo[axis] + 1
    }
}

/// A triangle's cells, as [`Cells::classify`] finds them.
pub(super) enum Overlap {
    /// The cells `base + corner[bit]` for the bits of `mask` (bit `i + 2j + 4k` is the cell `i, j,
    /// k` up from the footprint's corner `base`).
    Small { base: usize, mask: u32 },
    /// A footprint of more than two cells on some axis.
    Large(Footprint),
}

impl Cells {
    /// The insertion geometry of a non-empty grid.
    ///
    /// The footprint is computed in f32 as `(p ∓ pad − min)·inv`, three roundings on values up to
    /// `2A + pad` (A the box's coordinate magnitude) and an inverse within 2u of `1/size`: off by
    /// at most `3u·(A + pad)/size + 3.01u·(res + pad/size)` cells. The pad is the margin plus
    /// `8u·(A/size + res + 1 + 2·margin/size)` cells, which exceeds that, so the f32 footprint holds
    /// every cell whose box enlarged by the margin meets the triangle's bounds.
    pub fn new(shape: &Shape) -> Cells {
        const U: f64 = f32::EPSILON as f64 * 0.5; // 2^-24
        let f = |v: Vec3| [v.x, v.y, v.z].map(f64::from);
        let size = f(shape.cell_size);
        let margin = f(shape.margin);
        let inv = size.map(|s| 1.0 / s);
        let scale = f64::from(
            shape
                .bounds
                .min
                .abs()
                .max(shape.bounds.max.abs())
                .max_element(),
        );
        let pad = [0, 1, 2].map(|a| {
            let cells = 8.0
                * U
                * (scale * inv[a] + f64::from(shape.res[a]) + 1.0 + 2.0 * margin[a] * inv[a]);
            ((margin[a] + cells * size[a]) * (1.0 + 1.0 / 1_048_576.0)) as f32
        });
        let resf = Vec3::new(
            shape.res[0] as f32,
            shape.res[1] as f32,
            shape.res[2] as f32,
        );
        // Each `res − 1` is exact in f32 up to 2^24: then the clamp to the last cell is done on
        // the f32 value, before truncation (truncation is monotone and keeps integers).
        let exact_cap = shape.res.iter().all(|r| (1..=(1 << 24) + 1).contains(r));
        // Above 2^24 cells the cap is 2^30, at or past every axis's last cell (`Shape`'s bound),
        // so the clamp to the last cell after truncation finds every cell.
        debug_assert!(shape.res.iter().all(|&r| r <= MAX_AXIS_CELLS));
        let cap = |a: usize| {
            if exact_cap {
                shape.res[a].saturating_sub(1) as f32
            } else {
                MAX_AXIS_CELLS as f32
            }
        };
        let stride = [
            1,
            shape.res[0] as usize,
            shape.res[0] as usize * shape.res[1] as usize,
        ];
        Cells {
            res: shape.res,
            stride,
            corner: core::array::from_fn(|b| {
                (b & 1) * stride[0] + ((b >> 1) & 1) * stride[1] + (b >> 2) * stride[2]
            }),
            min32: shape.bounds.min.into(),
            inv32: (resf / (shape.bounds.max - shape.bounds.min)).into(),
            pad32: Vec3::from(pad).into(),
            cap32: Vec3A::new(cap(0), cap(1), cap(2)),
            exact_cap,
            min: f(shape.bounds.min),
            inv,
            half: [0, 1, 2].map(|a| (0.5 + margin[a] * inv[a]) * ROUNDING_SLACK),
        }
    }

    /// The flat index of cell `c`.
    #[inline(always)]
    pub fn index(&self, c: [u32; 3]) -> usize {
        // `stride[0]` is 1.
        c[0] as usize + c[1] as usize * self.stride[1] + c[2] as usize * self.stride[2]
    }

    /// Coordinate `p` on `axis` in cell units.
    #[inline(always)]
    fn local(&self, p: f32, axis: usize) -> f64 {
        (f64::from(p) - self.min[axis]) * self.inv[axis]
    }

    /// A superset of the cells whose enlarged boxes meet the triangle's bounds (clamped to the
    /// grid), in f32 (see [`Cells::new`] for why it misses none).
    #[inline(always)]
    pub fn footprint(&self, tri: &[Vec3; 3]) -> Footprint {
        // Four lanes at a time (the fourth unused); coordinates are finite, so `min`/`max` need
        // no NaN handling.
        let [p, q, r] = tri.map(Vec3A::from);
        let lo = p.min(q).min(r);
        let hi = p.max(q).max(r);
        let l = (lo - self.pad32 - self.min32) * self.inv32;
        let h = (hi + self.pad32 - self.min32) * self.inv32;
        // The cell of a value is its floor clamped to the grid: clamp to [0, cap] first (NaN
        // fails `f > 0` and becomes 0), truncate (floor, for a non-negative value), then clamp to
        // the last cell, which the cap already did when it is the last cell (`exact_cap`).
        let clamp = |v: Vec3A| {
            let v = Vec3A::select(v.cmpgt(Vec3A::ZERO), v, Vec3A::ZERO);
            Vec3A::select(v.cmplt(self.cap32), v, self.cap32)
        };
        let (l, h) = (clamp(l), clamp(h));
        let cell = |f: f32, a: usize| {
            debug_assert!((0.0..=1_073_741_824.0).contains(&f));
            // SAFETY: `f` is in [0, cap], cap at most 2^30, so it is not NaN and its truncation
            // fits an i32.
            let c = unsafe { f.to_int_unchecked::<i32>() } as u32;
            if self.exact_cap {
                debug_assert!(c < self.res[a]);
                c
            } else {
                c.min(self.res[a] - 1)
            }
        };
        Footprint {
            lo: [cell(l.x, 0), cell(l.y, 1), cell(l.z, 2)],
            hi: [cell(h.x, 0), cell(h.y, 1), cell(h.z, 2)],
        }
    }

    /// Calls `emit(cell)` for every cell the triangle overlaps: every cell whose box, enlarged by
    /// the margin, meets it (and perhaps a few that only come within the rounding slack of it).
    /// With `exact == false`, every cell of its footprint. (The build inlines the same with its
    /// own emission, build.rs.)
    #[cfg(test)]
    pub fn for_each(&self, tri: &[Vec3; 3], exact: bool, emit: &mut impl FnMut(u32)) {
        match self.classify(tri, exact) {
            Overlap::Small { base, mut mask } => {
                while mask != 0 {
                    let bit = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    emit((base + self.corner[bit & 7]) as u32);
                }
            }
            Overlap::Large(fp) => self.for_each_large(tri, &fp, exact, emit),
        }
    }

    /// The cells of a triangle as a mask when its footprint has at most two cells per axis
    /// (nearly every triangle of a well-shaped scene), else the footprint for
    /// [`Cells::for_each_large`].
    #[inline(always)]
    pub fn classify(&self, tri: &[Vec3; 3], exact: bool) -> Overlap {
        let fp = self.footprint(tri);
        let n = [0, 1, 2].map(|a| fp.hi[a] - fp.lo[a]);
        if (n[0] | n[1] | n[2]) > 1 {
            return Overlap::Large(fp);
        }
        // The footprint as bits i + 2j + 4k (the cell i, j, k up from its corner). A single cell
        // or a column needs no test: the (connected) triangle crosses a column from end to end
        // while lying within its enlarged cross-section, so it meets every cell of it.
        let mut mask = u32::from(FOOTPRINT_MASK[(n[0] + 2 * n[1] + 4 * n[2]) as usize & 7]);
        if exact && n[0] + n[1] + n[2] >= 2 {
            mask &= self.small(tri, &fp, n.map(|n| n > 0));
        }
        Overlap::Small {
            base: self.index(fp.lo),
            mask,
        }
    }

    /// [`Cells::for_each`] for a footprint of more than two cells on some axis: each cell of `fp`
    /// at most once and none outside it (the build makes room for the footprint's cells and
    /// stores them unchecked, build.rs).
    #[inline(never)]
    pub fn for_each_large(
        &self,
        tri: &[Vec3; 3],
        fp: &Footprint,
        exact: bool,
        emit: &mut impl FnMut(u32),
    ) {
        if let Some((base, mut mask)) = self.medium_cells(tri, fp, exact) {
            while mask != 0 {
                let bit = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                emit(self.medium_cell(base, bit) as u32);
            }
            return;
        }
        let thick = [0, 1, 2].map(|a| fp.hi[a] > fp.lo[a]);
        if !exact || thick.iter().filter(|&&t| t).count() < 2 {
            self.for_box(fp, emit);
        } else {
            let q = tri.map(|p| [0, 1, 2].map(|a| self.local(p[a], a)));
            // A footprint one cell thick on an axis is cheaper by rows (one projection decides).
            let slabs = if thick == [true; 3] {
                slab_axis(&q, fp)
            } else {
                None
            };
            match slabs {
                Some(s) => self.slabs(&q, fp, s, emit),
                None => self.overlapped(&q, fp, thick, emit),
            }
        }
    }

    /// For a footprint of at most [`MEDIUM_CELLS`] cells an axis, more than one on two or three
    /// axes, and `exact`: the flat index of its corner and the mask of the cells the triangle
    /// overlaps ([`Cells::medium`]; [`Cells::medium_cell`] turns a bit into a cell). `None` for
    /// the other footprints, which [`Cells::for_each_large`] lists by rows or whole.
    #[inline(always)]
    pub fn medium_cells(
        &self,
        tri: &[Vec3; 3],
        fp: &Footprint,
        exact: bool,
    ) -> Option<(usize, u64)> {
        let thick = [0, 1, 2].map(|a| fp.hi[a] > fp.lo[a]);
        let medium = exact
            && thick.iter().filter(|&&t| t).count() >= 2
            && (0..3).all(|a| fp.len(a) <= MEDIUM_CELLS);
        medium.then(|| (self.index(fp.lo), self.medium(tri, fp, thick)))
    }

    /// The cell of bit `bit` (`< 64`) of a [`Cells::medium_cells`] mask whose corner is `base`.
    #[inline(always)]
    pub fn medium_cell(&self, base: usize, bit: usize) -> usize {
        // `stride[0]` is 1.
        base + (bit & 3) + ((bit >> 2) & 3) * self.stride[1] + ((bit >> 4) & 3) * self.stride[2]
    }

    /// The cells a triangle overlaps among those of a footprint of at most [`MEDIUM_CELLS`] cells
    /// per axis, two or more on two or three axes (`thick`), as bits `i + 4j + 16k` (the cell `i,
    /// j, k` up from the footprint's corner): [`Cells::small`]'s tests on a 4×4×4 block, each
    /// projection's edges as a mask of its 4×4 cells, four at a time, and the plane: on hair-50k
    /// 793 instructions a footprint, against 1 257 by rows ([`Cells::overlapped`];
    /// docs/performance.md, "Stop 37").
    ///
    /// In f32, in cell units from the footprint's corner (values below `4 + 2·margin`): the
    /// roundings of each test are below `24u` of its width (twice `small`'s bound, for twice the
    /// extent), well inside the rounding slack.
    #[inline(never)]
    fn medium(&self, tri: &[Vec3; 3], fp: &Footprint, thick: [bool; 3]) -> u64 {
        let q = tri.map(|p| [0, 1, 2].map(|a| (self.local(p[a], a) - f64::from(fp.lo[a])) as f32));
        let half = self.half.map(|h| h as f32);
        let grid = |x: usize, y: usize| grid_mask(q.map(|v| [v[x], v[y]]), [half[x], half[y]]);
        // Each projection's 16 bits spread over the third axis: (x, y) over k, (x, z) (bits i +
        // 4k) over j, (y, z) (bits j + 4k) over i.
        let over_k = |m: u32| u64::from(m) * LAYERS[3];
        let over_j = |m: u32| {
            (0..4).fold(0u64, |acc, k| {
                acc | (u64::from((m >> (4 * k)) & 0xf) * 0x1111) << (16 * k)
            })
        };
        let over_i = |m: u32| {
            (0..4).fold(0u64, |acc, k| {
                acc | u64::from(NIBBLES[((m >> (4 * k)) & 0xf) as usize]) << (16 * k)
            })
        };
        // The footprint's own cells (`n + 1` per axis, at most 4).
        let n = [0, 1, 2].map(|a| (fp.hi[a] - fp.lo[a]) as usize & 3);
        let footprint = ((1u64 << (n[0] + 1)) - 1) * ROWS[n[1]] * LAYERS[n[2]];
        let mask = match thick {
            // One cell thick on an axis: the projection onto the other two decides (for_each).
            [false, _, _] => over_i(grid(1, 2)),
            [_, false, _] => over_j(grid(0, 2)),
            [_, _, false] => over_k(grid(0, 1)),
            _ => {
                over_k(grid(0, 1))
                    & over_j(grid(0, 2))
                    & over_i(grid(1, 2))
                    & grid_plane_mask(&q, half)
            }
        };
        mask & footprint
    }

    /// The cells a triangle overlaps among those of a footprint of at most two cells per axis,
    /// two on two or three axes (`thick`), as bits `i + 2j + 4k` (the cell `i, j, k` up from the
    /// footprint's corner): the separating axes cell by cell, four cells at a time — each
    /// projection's edges as a mask of its 2×2 cells, and the plane.
    ///
    /// In f32, in cell units from the footprint's corner (converted from f64 cell units, so the
    /// values are below 2 + 2·margin): the few roundings of each test are below 2^-20 of its
    /// width, well inside the rounding slack.
    #[inline(never)]
    fn small(&self, tri: &[Vec3; 3], fp: &Footprint, thick: [bool; 3]) -> u32 {
        let q = tri.map(|p| [0, 1, 2].map(|a| (self.local(p[a], a) - f64::from(fp.lo[a])) as f32));
        let half = self.half.map(|h| h as f32);
        // The projection onto axes (x, y), its 2×2 mask spread to the cells at offset 0 on the
        // third axis.
        let quad = |x: usize, y: usize| {
            let m = quad_mask(q.map(|v| [v[x], v[y]]), [half[x], half[y]]);
            let (wx, wy) = (1 << x, 1 << y);
            (m & 1) | ((m >> 1) & 1) << wx | ((m >> 2) & 1) << wy | ((m >> 3) & 1) << (wx + wy)
        };
        match thick {
            // One cell thick on an axis: the projection onto the other two decides (for_each).
            [false, _, _] => quad(1, 2),
            [_, false, _] => quad(2, 0),
            [_, _, false] => quad(0, 1),
            _ => {
                let (xy, yz, zx) = (quad(0, 1), quad(1, 2), quad(2, 0));
                let mask = (xy | xy << 4) & (yz | yz << 1) & (zx | zx << 2);
                mask & plane_mask(&q, half)
            }
        }
    }

    /// Every cell of `fp`.
    #[inline(always)]
    fn for_box(&self, fp: &Footprint, emit: &mut impl FnMut(u32)) {
        for z in fp.lo[2]..=fp.hi[2] {
            for y in fp.lo[1]..=fp.hi[1] {
                let row = self.index([fp.lo[0], y, z]);
                for x in 0..=(fp.hi[0] - fp.lo[0]) as usize {
                    emit((row + x) as u32);
                }
            }
        }
    }

    /// The cells of `fp` the triangle (`q`, in cell units) overlaps, for a footprint at least two
    /// cells thick on two or three axes (`thick`): runs of cells by rows.
    #[inline(never)]
    fn overlapped(
        &self,
        q: &[[f64; 3]; 3],
        fp: &Footprint,
        thick: [bool; 3],
        emit: &mut impl FnMut(u32),
    ) {
        // Rows along `v`, runs along `u`; `w` is the third axis. With a footprint one cell thick
        // on `w`, the enlarged cells hold the triangle's whole extent along `w`, so only the
        // projection onto (u, v) decides. Otherwise `w` is the normal's largest axis, so that
        // each column (u, v) holds a run of at most about three cells along `w`.
        let normal = cross(sub(q[1], q[0]), sub(q[2], q[0]));
        let w = match thick {
            [false, _, _] => 0,
            [_, false, _] => 1,
            [_, _, false] => 2,
            _ => largest_axis(normal),
        };
        let (a, b) = ((w + 1) % 3, (w + 2) % 3);
        // Fewer rows than columns: rows cost a setup each.
        let (u, v) = if fp.len(a) >= fp.len(b) {
            (a, b)
        } else {
            (b, a)
        };
        let uv = Rows::new(q, u, v, &self.half);
        let span = |axis: usize| (f64::from(fp.lo[axis]) + 0.5, f64::from(fp.hi[axis]) + 0.5);
        let (u_span, w_span) = (span(u), span(w));
        if !thick[w] {
            for j in fp.lo[v]..=fp.hi[v] {
                let cv = f64::from(j) + 0.5;
                let Some((i0, i1)) = cells_in(uv.solve(cv, u_span)) else {
                    continue;
                };
                let row = j as usize * self.stride[v] + fp.lo[w] as usize * self.stride[w];
                for i in i0..=i1 {
                    emit((row + i as usize * self.stride[u]) as u32);
                }
            }
            return;
        }
        let vw = Rows::new(q, w, v, &self.half);
        let wu = Rows::new(q, w, u, &self.half);
        // The plane: n·(c − q0) within the vertices' projections onto the (computed, so not
        // exact: all three are projected) normal, widened by Σ |n_k|·half_k; solved for c_w per
        // column.
        let reach = (0..3).fold(0.0, |s, k| s + normal[k].abs() * self.half[k]);
        let dot = |v: [f64; 3]| normal[0] * v[0] + normal[1] * v[1] + normal[2] * v[2];
        let (d1, d2) = (dot(sub(q[1], q[0])), dot(sub(q[2], q[0])));
        let (plane_lo, plane_hi) = (d1.min(d2).min(0.0) - reach, d1.max(d2).max(0.0) + reach);
        let inv_nw = 1.0 / normal[w];
        for j in fp.lo[v]..=fp.hi[v] {
            let cv = f64::from(j) + 0.5;
            let Some((i0, i1)) = cells_in(uv.solve(cv, u_span)) else {
                continue;
            };
            let w_row = vw.solve(cv, w_span);
            if !(w_row.0 <= w_row.1) {
                continue;
            }
            let row = j as usize * self.stride[v];
            let off_v = normal[v] * (cv - q[0][v]);
            for i in i0..=i1 {
                let cu = f64::from(i) + 0.5;
                let (mut lo, mut hi) = wu.solve(cu, w_row);
                let rest = normal[u] * (cu - q[0][u]) + off_v;
                // n_w ≠ 0 unless the normal vanished in rounding (then the plane says nothing).
                if inv_nw.is_finite() {
                    let t1 = q[0][w] + (plane_lo - rest) * inv_nw;
                    let t2 = q[0][w] + (plane_hi - rest) * inv_nw;
                    let (l, h) = if t1 < t2 { (t1, t2) } else { (t2, t1) };
                    if l > lo {
                        lo = l;
                    }
                    if h < hi {
                        hi = h;
                    }
                }
                let Some((k0, k1)) = cells_in((lo, hi)) else {
                    continue;
                };
                let column = row + i as usize * self.stride[u];
                for k in k0..=k1 {
                    emit((column + k as usize * self.stride[w]) as u32);
                }
            }
        }
    }
}

/// The cells of a footprint of `1 + n_a` cells on each axis `a` (`n_a` 0 or 1) as bits `i + 2j +
/// 4k`, indexed by `n_0 + 2n_1 + 4n_2`.
const FOOTPRINT_MASK: [u8; 8] = {
    let mut t = [0u8; 8];
    let mut i = 0;
    while i < 8 {
        let mut m = 1u8;
        if i & 1 != 0 {
            m |= m << 1;
        }
        if i & 2 != 0 {
            m |= m << 2;
        }
        if i & 4 != 0 {
            m |= m << 4;
        }
        t[i] = m;
        i += 1;
    }
    t
};

/// The most cells per axis of a footprint that [`Cells::medium`] takes.
const MEDIUM_CELLS: u32 = 4;

/// A row of [`Cells::medium`]'s bits (4 bits) repeated over the first `n + 1` rows of a 16-bit
/// layer, as a multiplier.
const ROWS: [u64; 4] = [0x1, 0x11, 0x111, 0x1111];

/// A 16-bit layer repeated over the first `n + 1` layers, as a multiplier.
const LAYERS: [u64; 4] = [0x1, 0x1_0001, 0x1_0001_0001, 0x1_0001_0001_0001];

/// Each of 4 bits spread to a nibble (bit `b` to bits `4b..4b + 4`).
const NIBBLES: [u16; 16] = {
    let mut t = [0u16; 16];
    let mut m = 0;
    while m < 16 {
        let mut b = 0;
        while b < 4 {
            if m & (1 << b) != 0 {
                t[m] |= 0xf << (4 * b);
            }
            b += 1;
        }
        m += 1;
    }
    t
};

/// The centres of a 4×4 block's cells on the first axis.
const GRID_X: Vec4 = Vec4::new(0.5, 1.5, 2.5, 3.5);

/// Which of the 4×4 cells centred at `(0.5 + i, 0.5 + j)`, `i, j < 4`, of half extent `half` the
/// projected triangle `p` may meet (bit `i + 4j`): [`quad_mask`] on a larger block.
#[inline(always)]
fn grid_mask(p: [[f32; 2]; 3], half: [f32; 2]) -> u32 {
    let mut mask = 0xffff;
    for i in 0..3 {
        let edge = edge_slab(p, i, half);
        let (lo, hi) = (Vec4::splat(edge.lo), Vec4::splat(edge.hi));
        // `a·(x − s0) + b·(y − s1)` at the cell centres: the columns' terms in lanes, each row's
        // term splat from its lane (the same products as one expression per cell).
        let [cols, rows] =
            [0, 1].map(|k| Vec4::splat(edge.n[k]) * (GRID_X - Vec4::splat(edge.from[k])));
        let inside = |v: Vec4| (!(v.cmplt(lo) | v.cmpgt(hi))).bitmask();
        mask &= inside(cols + Vec4::splat(rows.x))
            | inside(cols + Vec4::splat(rows.y)) << 4
            | inside(cols + Vec4::splat(rows.z)) << 8
            | inside(cols + Vec4::splat(rows.w)) << 12;
    }
    mask
}

/// Which of the 4×4×4 cells centred at `(0.5 + i, 0.5 + j, 0.5 + k)` of half extent `half` the
/// triangle's plane may cross (bit `i + 4j + 16k`): [`plane_mask`] on a larger block.
#[inline(always)]
fn grid_plane_mask(q: &[[f32; 3]; 3], half: [f32; 3]) -> u64 {
    let plane = plane_slab(q, half);
    let (lo, hi) = (Vec4::splat(plane.lo), Vec4::splat(plane.hi));
    let [cols, rows, layers] =
        [0, 1, 2].map(|a| Vec4::splat(plane.n[a]) * (GRID_X - Vec4::splat(plane.from[a])));
    let inside = |v: Vec4| u64::from((!(v.cmplt(lo) | v.cmpgt(hi))).bitmask());
    let layer = |z: f32| {
        let yz = rows + Vec4::splat(z);
        inside(cols + Vec4::splat(yz.x))
            | inside(cols + Vec4::splat(yz.y)) << 4
            | inside(cols + Vec4::splat(yz.z)) << 8
            | inside(cols + Vec4::splat(yz.w)) << 12
    };
    layer(layers.x) | layer(layers.y) << 16 | layer(layers.z) << 32 | layer(layers.w) << 48
}

/// A separating axis of the masks: the cells whose centres `c` give `n·(c − from)` outside
/// `[lo, hi]` are separated from the triangle.
struct Slab<const D: usize> {
    n: [f32; D],
    from: [f32; D],
    lo: f32,
    hi: f32,
}

/// Edge `i` of the projected triangle `p` (from vertex `i` to `i + 1`) against cells of half
/// extent `half`: its normal, and the triangle's projection onto it (the edge's vertices at 0, the
/// opposite one at `far`, relative to the edge's first vertex) widened by a cell's.
#[inline(always)]
fn edge_slab(p: [[f32; 2]; 3], i: usize, half: [f32; 2]) -> Slab<2> {
    let (s, e, o) = (p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
    let (a, b) = (e[1] - s[1], s[0] - e[0]);
    let far = a * (o[0] - s[0]) + b * (o[1] - s[1]);
    let r = a.abs() * half[0] + b.abs() * half[1];
    Slab {
        n: [a, b],
        from: s,
        lo: far.min(0.0) - r,
        hi: far.max(0.0) + r,
    }
}

/// The triangle's plane against cells of half extent `half`: the normal `n`, computed, need not be
/// exact — any axis separates when the projections miss — so all three vertices are projected onto
/// it (`0`, `d1`, `d2` relative to `q0`), widened by a cell's projection.
#[inline(always)]
fn plane_slab(q: &[[f32; 3]; 3], half: [f32; 3]) -> Slab<3> {
    let d = |i: usize| [0, 1, 2].map(|a| q[i][a] - q[0][a]);
    let (e1, e2) = (d(1), d(2));
    let n = [
        e1[1] * e2[2] - e1[2] * e2[1],
        e1[2] * e2[0] - e1[0] * e2[2],
        e1[0] * e2[1] - e1[1] * e2[0],
    ];
    let dot = |v: [f32; 3]| n[0] * v[0] + n[1] * v[1] + n[2] * v[2];
    let (d1, d2) = (dot(e1), dot(e2));
    let r = n[0].abs() * half[0] + n[1].abs() * half[1] + n[2].abs() * half[2];
    Slab {
        n,
        from: q[0],
        lo: d1.min(d2).min(0.0) - r,
        hi: d1.max(d2).max(0.0) + r,
    }
}

/// The centres of the 2×2 cells of [`quad_mask`], on the first and the second axis.
const QUAD_X: Vec4 = Vec4::new(0.5, 1.5, 0.5, 1.5);
const QUAD_Y: Vec4 = Vec4::new(0.5, 0.5, 1.5, 1.5);

/// Which of the 2×2 cells centred at `(0.5 + i, 0.5 + j)`, `i, j ∈ {0, 1}`, of half extent
/// `half` the projected triangle `p` may meet (bit `i + 2j`): each edge's normal separates the
/// cells whose projection onto it misses the triangle's ([`edge_slab`]). A NaN keeps the cell.
#[inline(always)]
fn quad_mask(p: [[f32; 2]; 3], half: [f32; 2]) -> u32 {
    let mut mask = 0b1111;
    for i in 0..3 {
        let Slab {
            n: [a, b],
            from: s,
            lo,
            hi,
        } = edge_slab(p, i, half);
        let v = Vec4::splat(a) * (QUAD_X - Vec4::splat(s[0]))
            + Vec4::splat(b) * (QUAD_Y - Vec4::splat(s[1]));
        mask &= (!(v.cmplt(Vec4::splat(lo)) | v.cmpgt(Vec4::splat(hi)))).bitmask();
    }
    mask
}

/// Which of the 2×2×2 cells centred at `(0.5 + i, 0.5 + j, 0.5 + k)` of half extent `half` the
/// triangle's plane may cross (bit `i + 2j + 4k`; [`plane_slab`]). A NaN keeps the cell.
#[inline(always)]
fn plane_mask(q: &[[f32; 3]; 3], half: [f32; 3]) -> u32 {
    let Slab { n, from, lo, hi } = plane_slab(q, half);
    let (lo, hi) = (Vec4::splat(lo), Vec4::splat(hi));
    let v = Vec4::splat(n[0]) * (QUAD_X - Vec4::splat(from[0]))
        + Vec4::splat(n[1]) * (QUAD_Y - Vec4::splat(from[1]));
    let mut mask = 0;
    for (k, cz) in [0.5f32, 1.5].into_iter().enumerate() {
        let w = v + Vec4::splat(n[2] * (cz - from[2]));
        mask |= (!(w.cmplt(lo) | w.cmpgt(hi))).bitmask() << (4 * k);
    }
    mask
}

/// The cells `k` whose centres `k + 0.5` lie in `[lo, hi]`, for bounds that start inside a
/// footprint (`lo ≥ 0.5`) and were only narrowed: `None` when there are none.
#[inline(always)]
fn cells_in((lo, hi): (f64, f64)) -> Option<(u32, u32)> {
    let (a, b) = (lo - 0.5, hi - 0.5);
    // Both are at least `a ≥ 0` when the range is not empty, so truncation is floor, and
    // `ceil(a) = trunc(a) + (trunc(a) < a)`; huge values saturate and stay out of range.
    if !(a <= b) {
        return None;
    }
    let t = a as u32;
    let first = t + u32::from(f64::from(t) < a);
    let last = b as u32;
    (first <= last).then_some((first, last))
}

/// One axis-plane projection of the triangle, as constraints on the centre `(x, y)` of an
/// enlarged cell (`x` on the axis solved for, `y` on the given one): for each edge with normal
/// `(a, b)`, `lo ≤ a·x + b·y ≤ hi`, the triangle's projection onto the normal widened by the
/// cell's projected half extent. Both sides are kept: a needle's widened tip would otherwise reach
/// far beyond it.
struct Projection {
    a: [f64; 3],
    b: [f64; 3],
    lo: [f64; 3],
    hi: [f64; 3],
}

impl Projection {
    /// The projection with vertices `p` (cell units; `x` the coordinate solved for, `y` the given
    /// one) against cells of half extent `half`.
    #[inline(always)]
    fn new(p: [[f64; 2]; 3], half: [f64; 2]) -> Projection {
        let mut out = Projection {
            a: [0.0; 3],
            b: [0.0; 3],
            lo: [0.0; 3],
            hi: [0.0; 3],
        };
        for i in 0..3 {
            let (s, e, o) = (p[i], p[(i + 1) % 3], p[(i + 2) % 3]);
            let (a, b) = (e[1] - s[1], s[0] - e[0]);
            let k = a * s[0] + b * s[1];
            // The opposite vertex's side, from differences (accurate for small triangles far
            // from the grid's corner).
            let far = a * (o[0] - s[0]) + b * (o[1] - s[1]);
            let r = a.abs() * half[0] + b.abs() * half[1];
            out.a[i] = a;
            out.b[i] = b;
            out.lo[i] = k + far.min(0.0) - r;
            out.hi[i] = k + far.max(0.0) + r;
        }
        out
    }
}

/// A [`Projection`] solved row by row: per edge, `x ≥ (lower − b·y)·inv` and `x ≤ (upper −
/// b·y)·inv` (the projection's bounds, swapped for a negative `a`, `inv = 1/a`); an edge with
/// `a = 0` constrains `y` alone (`lo ≤ b·y ≤ hi`).
struct Rows {
    b: [f64; 3],
    lower: [f64; 3],
    upper: [f64; 3],
    inv: [f64; 3],
    /// Whether some edge has `a = 0` (then `solve` checks `y` against it).
    flat: bool,
    p: Projection,
}

impl Rows {
    #[inline(always)]
    fn new(q: &[[f64; 3]; 3], x: usize, y: usize, half: &[f64; 3]) -> Rows {
        let p = Projection::new(q.map(|v| [v[x], v[y]]), [half[x], half[y]]);
        let mut r = Rows {
            b: p.b,
            lower: [f64::NEG_INFINITY; 3],
            upper: [f64::INFINITY; 3],
            inv: [0.0; 3],
            flat: false,
            p,
        };
        for i in 0..3 {
            let a = r.p.a[i];
            if a == 0.0 {
                // No bound on x from this edge (−∞ − b·y stays −∞: `inv = 1` keeps it so).
                r.flat = true;
                r.b[i] = 0.0;
                r.inv[i] = 1.0;
            } else {
                r.inv[i] = 1.0 / a;
                (r.lower[i], r.upper[i]) = if a > 0.0 {
                    (r.p.lo[i], r.p.hi[i])
                } else {
                    (r.p.hi[i], r.p.lo[i])
                };
            }
        }
        r
    }

    /// The centres `x` allowed at `y`, narrowing `(lo, hi)`; `lo > hi` when none is. A NaN bound
    /// (0·∞ for a vanishing `a`) never narrows.
    #[inline(always)]
    fn solve(&self, y: f64, (mut lo, mut hi): (f64, f64)) -> (f64, f64) {
        if self.flat {
            let p = &self.p;
            for i in 0..3 {
                let by = p.b[i] * y;
                if p.a[i] == 0.0 && !(by >= p.lo[i] && by <= p.hi[i]) {
                    return (1.0, 0.0);
                }
            }
        }
        for i in 0..3 {
            let by = self.b[i] * y;
            let l = (self.lower[i] - by) * self.inv[i];
            let h = (self.upper[i] - by) * self.inv[i];
            if l > lo {
                lo = l;
            }
            if h < hi {
                hi = h;
            }
        }
        (lo, hi)
    }
}

#[inline(always)]
fn sub(p: [f64; 3], q: [f64; 3]) -> [f64; 3] {
    [p[0] - q[0], p[1] - q[1], p[2] - q[2]]
}

#[inline(always)]
fn cross(u: [f64; 3], w: [f64; 3]) -> [f64; 3] {
    [
        u[1] * w[2] - u[2] * w[1],
        u[2] * w[0] - u[0] * w[2],
        u[0] * w[1] - u[1] * w[0],
    ]
}

/// The axis of `n`'s largest component (ties to the lower axis).
#[inline(always)]
fn largest_axis(n: [f64; 3]) -> usize {
    let m = n.map(f64::abs);
    if m[0] >= m[1] && m[0] >= m[2] {
        0
    } else if m[1] >= m[2] {
        1
    } else {
        2
    }
}
