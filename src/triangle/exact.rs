//! Exact arithmetic from the f32 inputs, for the few decisions the floating-point filters leave
//! open: the sign of an edge function and the correctly rounded `t`.
//!
//! Every f32 is an integer multiple of 2^-149 of magnitude below 2^128, so in units of 2^-149 it is
//! an integer of at most 277 bits ([`Coord`], 5 limbs). A difference of two is below 2^279. A
//! product of two differences is below 2^558 (10 limbs) and a triple product (the direction or a
//! vertex and two differences) below 6·2^836 < 2^839 ([`Triple`], 15 limbs), in units of 2^-447.
//! Comparing `t = N/D` with an f32 midpoint `m = k·2^-150` compares `N·2^150` (below 2^989) with
//! `k·|D|`, computed only when it is below 2^1024 (otherwise it is certainly the larger):
//! [`Wide`], 16 limbs. Nothing here overflows, and nothing rounds.
//!
//! The stage is rare and runs inside a query, so it keeps its stack small: the inputs stay f32 and
//! each difference is formed where it is used.

use core::cmp::Ordering;

use glam::Vec3;

/// A signed integer of `L` 64-bit limbs (least significant first), sign and magnitude.
#[derive(Clone, Copy, Debug)]
struct Int<const L: usize> {
    neg: bool,
    mag: [u64; L],
}

/// An f32 coordinate, or the difference of two, in units of 2^-149.
type Coord = Int<5>;
/// A triple product (and sums of three).
type Triple = Int<15>;
/// The midpoint comparisons.
type Wide = Int<16>;

fn cmp_mag(a: &[u64], b: &[u64]) -> Ordering {
    let n = a.len().max(b.len());
    for i in (0..n).rev() {
        let (x, y) = (
            a.get(i).copied().unwrap_or(0),
            b.get(i).copied().unwrap_or(0),
        );
        if x != y {
            return x.cmp(&y);
        }
    }
    Ordering::Equal
}

/// `a += b`; bits past `a` are dropped (the size argument in the module comment says there are
/// none).
fn add_mag(a: &mut [u64], b: &[u64]) {
    let mut carry = 0u128;
    for (i, x) in a.iter_mut().enumerate() {
        let s = u128::from(*x) + u128::from(b.get(i).copied().unwrap_or(0)) + carry;
        *x = s as u64;
        carry = s >> 64;
    }
    debug_assert_eq!(carry, 0, "exact arithmetic overflowed its limbs");
}

/// `a = a − b` (`a ≥ b`) or, with `reverse`, `a = b − a` (`b ≥ a`).
fn sub_mag(a: &mut [u64], b: &[u64], reverse: bool) {
    let mut borrow = 0u64;
    for (i, x) in a.iter_mut().enumerate() {
        let y = b.get(i).copied().unwrap_or(0);
        let (hi, lo) = if reverse { (y, *x) } else { (*x, y) };
        let (d, b1) = hi.overflowing_sub(lo);
        let (d, b2) = d.overflowing_sub(borrow);
        *x = d;
        borrow = u64::from(b1 | b2);
    }
    debug_assert_eq!(borrow, 0, "sub_mag's operands are out of order");
}

impl<const L: usize> Int<L> {
    const ZERO: Self = Int {
        neg: false,
        mag: [0; L],
    };

    fn is_zero(&self) -> bool {
        self.mag.iter().all(|&x| x == 0)
    }

    /// The number of significant bits of the magnitude.
    fn bit_len(&self) -> u32 {
        match self.mag.iter().rposition(|&x| x != 0) {
            Some(top) => 64 * top as u32 + (64 - self.mag[top].leading_zeros()),
            None => 0,
        }
    }

    /// −1, 0 or 1.
    fn signum(&self) -> i8 {
        if self.is_zero() {
            0
        } else if self.neg {
            -1
        } else {
            1
        }
    }

    /// `self += other` (no bits lost, by the size argument).
    fn add_assign<const N: usize>(&mut self, other: &Int<N>) {
        if self.neg == other.neg {
            add_mag(&mut self.mag, &other.mag);
        } else {
            match cmp_mag(&self.mag, &other.mag) {
                Ordering::Equal => self.mag = [0; L],
                Ordering::Greater => sub_mag(&mut self.mag, &other.mag, false),
                Ordering::Less => {
                    sub_mag(&mut self.mag, &other.mag, true);
                    self.neg = other.neg;
                }
            }
        }
        self.neg &= !self.is_zero();
    }

    /// `self −= other`.
    fn sub_assign<const N: usize>(&mut self, other: &Int<N>) {
        self.neg = !self.neg;
        self.add_assign(other);
        self.neg = !self.neg && !self.is_zero();
    }

    /// `self − other`.
    fn sub(mut self, other: &Self) -> Self {
        self.sub_assign(other);
        self
    }

    /// The order of the signed values `self` and `other`.
    fn cmp_signed<const N: usize>(&self, other: &Int<N>) -> Ordering {
        match (self.signum(), other.signum()) {
            (a, b) if a != b => a.cmp(&b),
            (0, _) => Ordering::Equal,
            (1, _) => cmp_mag(&self.mag, &other.mag),
            _ => cmp_mag(&other.mag, &self.mag),
        }
    }

    /// `self · other` into `M` limbs (schoolbook; zero limbs, the common case for coordinates of
    /// similar magnitude, are skipped).
    fn mul<const M: usize, const N: usize>(&self, other: &Int<N>) -> Int<M> {
        let mut out = Int::<M>::ZERO;
        for (i, &x) in self.mag.iter().enumerate() {
            if x == 0 {
                continue;
            }
            let mut carry = 0u128;
            for (j, &y) in other.mag.iter().enumerate() {
                let Some(slot) = out.mag.get_mut(i + j) else {
                    debug_assert!(y == 0 && carry == 0, "exact product overflowed its limbs");
                    break;
                };
                let s = u128::from(x) * u128::from(y) + u128::from(*slot) + carry;
                *slot = s as u64;
                carry = s >> 64;
            }
            let mut k = i + N;
            while carry != 0 {
                let Some(slot) = out.mag.get_mut(k) else {
                    debug_assert!(false, "exact product overflowed its limbs");
                    break;
                };
                let s = u128::from(*slot) + carry;
                *slot = s as u64;
                carry = s >> 64;
                k += 1;
            }
        }
        out.neg = (self.neg != other.neg) && !out.is_zero();
        out
    }

    /// `self · 2^bits` in `M` limbs (no bits lost, by the size argument).
    fn shl<const M: usize>(&self, bits: u32) -> Int<M> {
        let (limbs, rem) = ((bits / 64) as usize, bits % 64);
        let mut out = Int::<M>::ZERO;
        out.neg = self.neg;
        for (i, o) in out.mag.iter_mut().enumerate() {
            let Some(src) = i.checked_sub(limbs) else {
                continue;
            };
            let lo = self.mag.get(src).copied().unwrap_or(0);
            let below = src
                .checked_sub(1)
                .and_then(|k| self.mag.get(k))
                .copied()
                .unwrap_or(0);
            *o = if rem == 0 {
                lo
            } else {
                (lo << rem) | (below >> (64 - rem))
            };
        }
        out
    }

    /// `mantissa · 2^shift` with the given sign.
    fn from_parts(neg: bool, mantissa: u64, shift: u32) -> Self {
        let mut one = Int::<1>::ZERO;
        one.mag[0] = mantissa;
        let mut out: Self = one.shl(shift);
        out.neg = neg && !out.is_zero();
        out
    }

    /// An approximation `(m, e)` with `self ≈ m · 2^(64·e)`, relative error below 2^-52.
    fn approx(&self) -> (f64, i32) {
        let top = self.mag.iter().rposition(|&x| x != 0).unwrap_or(0);
        let hi = u128::from(self.mag.get(top).copied().unwrap_or(0));
        let lo = top
            .checked_sub(1)
            .and_then(|k| self.mag.get(k))
            .map_or(0, |&x| u128::from(x));
        let m = ((hi << 64) | lo) as f64;
        (if self.neg { -m } else { m }, top as i32 - 1)
    }
}

impl Coord {
    /// `x · 2^149` exactly (an integer for every f32).
    fn from_f32(x: f32) -> Coord {
        let bits = x.to_bits();
        let exp = (bits >> 23) & 0xff;
        let frac = u64::from(bits & 0x7f_ffff);
        let (mantissa, shift) = if exp == 0 {
            (frac, 0)
        } else {
            (frac | 0x80_0000, exp - 1)
        };
        Coord::from_parts(bits >> 31 != 0, mantissa, shift)
    }
}

/// Whether `(p1 − p0) × (p2 − p0)` is exactly zero for the f32 corners `tri` (finite): the three
/// points are collinear (or repeated), so the triangle has no area. Each difference is exact in
/// 5 limbs, each product in 10: nothing rounds, unlike the same product in f64, which can be zero
/// for a triangle of area ~1 when its coordinates span 60 binary orders of magnitude.
pub(crate) fn edge_cross_is_zero(tri: &[Vec3; 3]) -> bool {
    let coord = |k: usize, a: usize| Coord::from_f32(tri[k].to_array()[a]);
    let edge = |k: usize| [0, 1, 2].map(|a| coord(k, a).sub(&coord(0, a)));
    let (e1, e2) = (edge(1), edge(2));
    (0..3).all(|a| {
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let p: Int<10> = e1[b].mul(&e2[c]);
        let q: Int<10> = e1[c].mul(&e2[b]);
        p.cmp_signed(&q) == Ordering::Equal
    })
}

/// `x · 2^bits` as an integer, for an `x` that is a multiple of `2^-bits` (f32 values and their
/// midpoints with `bits = 150`), `|x| < 2^129`.
fn scaled_integer(x: f64, bits: i32) -> Coord {
    let raw = x.to_bits();
    let exp = ((raw >> 52) & 0x7ff) as i32;
    let frac = raw & ((1u64 << 52) - 1);
    if exp == 0 && frac == 0 {
        return Coord::ZERO;
    }
    let (mantissa, e) = if exp == 0 {
        (frac, -1074)
    } else {
        (frac | (1 << 52), exp - 1075)
    };
    let shift = e + bits;
    let neg = raw >> 63 != 0;
    if shift >= 0 {
        Coord::from_parts(neg, mantissa, shift as u32)
    } else {
        // The low bits dropped here are zero for the values the callers pass.
        debug_assert_eq!(mantissa & ((1u64 << (-shift).min(63)) - 1), 0);
        Coord::from_parts(neg, mantissa >> (-shift).min(63), 0)
    }
}

/// `x · 2^k`, without overflow in the steps.
fn ldexp(mut x: f64, mut k: i32) -> f64 {
    while k != 0 {
        let step = k.clamp(-1000, 1000);
        x *= f64::from_bits(((step + 1023) as u64) << 52);
        k -= step;
    }
    x
}

/// The triple product `x·(y × z)` of vectors given per axis. Out of line: its frame is the stage's
/// largest and is freed before the caller goes on.
#[inline(never)]
fn triple(
    x: impl Fn(usize) -> Coord,
    y: impl Fn(usize) -> Coord,
    z: impl Fn(usize) -> Coord,
) -> Triple {
    let mut acc = Triple::ZERO;
    for k in 0..3 {
        let (i, j) = ((k + 1) % 3, (k + 2) % 3);
        let mut yz: Int<10> = y(i).mul(&z(j));
        yz.sub_assign(&y(j).mul::<10, 5>(&z(i)));
        acc.add_assign(&x(k).mul::<15, 10>(&yz));
    }
    acc
}

/// The ray and a triangle, exactly: the f32 inputs, from which every difference is formed exactly.
pub(super) struct ExactTriangle {
    org: [f32; 3],
    dir: [f32; 3],
    tri: [[f32; 3]; 3],
}

/// The f32 nearest above `x` (`+∞` above the largest).
fn next_up(x: f32) -> f32 {
    if x.is_nan() || x == f32::INFINITY {
        return x;
    }
    if x == 0.0 {
        return f32::from_bits(1);
    }
    let b = x.to_bits();
    f32::from_bits(if x > 0.0 { b + 1 } else { b - 1 })
}

/// The f32 nearest below `x`.
fn next_down(x: f32) -> f32 {
    -next_up(-x)
}

impl ExactTriangle {
    pub(super) fn new(org: Vec3, dir: Vec3, tri: &[Vec3; 3]) -> ExactTriangle {
        ExactTriangle {
            org: org.to_array(),
            dir: dir.to_array(),
            tri: tri.map(|p| p.to_array()),
        }
    }

    /// Coordinate `axis` of the direction.
    fn d(&self, axis: usize) -> Coord {
        Coord::from_f32(self.dir[axis])
    }

    /// Coordinate `axis` of vertex `v` minus the origin.
    fn rel(&self, v: usize, axis: usize) -> Coord {
        Coord::from_f32(self.tri[v][axis]).sub(&Coord::from_f32(self.org[axis]))
    }

    /// Coordinate `axis` of vertex `to` minus vertex `from`.
    fn edge(&self, from: usize, to: usize, axis: usize) -> Coord {
        Coord::from_f32(self.tri[to][axis]).sub(&Coord::from_f32(self.tri[from][axis]))
    }

    /// The edge function opposite vertex `v` (0, 1, 2: `U, V, W`) as a triple product:
    /// `d·(c×b)`, `d·(a×c)`, `d·(b×a)` for the translated vertices `a, b, c`.
    fn edge_function(&self, v: usize) -> Triple {
        let (p, q) = ((v + 2) % 3, (v + 1) % 3);
        triple(|k| self.d(k), |k| self.rel(p, k), |k| self.rel(q, k))
    }

    /// The exact sign of the edge function opposite vertex `edge`, in the order and with the signs
    /// of the floating-point test's `U, V, W` (each equals `|d_kz|` times the sheared edge
    /// function, docs/design.md).
    pub(super) fn edge_sign(&self, edge: usize) -> i8 {
        self.edge_function(edge).signum()
    }

    /// The barycentrics of the second and third vertex where the line crosses the plane: the
    /// exact edge functions' ratios, each within a few f64 ulps, rounded to f32 (`(0, 0)` for a
    /// line that does not cross the triangle's plane at one point). Only for edge functions of one
    /// sign (a hit), where their sum has no cancellation.
    pub(super) fn barycentrics(&self) -> (f32, f32) {
        let e = [0, 1, 2].map(|v| self.edge_function(v).approx());
        // A common scale: the largest of the three (the others, if far smaller, underflow to zero
        // harmlessly).
        let base = e.iter().map(|&(_, k)| k).max().unwrap_or(0);
        let sum = e
            .iter()
            .fold(0.0, |s, &(m, k)| s + ldexp(m, 64 * (k - base)));
        if sum == 0.0 {
            return (0.0, 0.0);
        }
        let ratio = |(m, k): (f64, i32)| (ldexp(m, 64 * (k - base)) / sum) as f32;
        (ratio(e[1]), ratio(e[2]))
    }

    /// The ray parameter where the line crosses the triangle's plane, rounded to the nearest f32
    /// (ties to even), `±∞` beyond the f32 range and `+0.0` for an exact zero. `None` for a line
    /// parallel to the plane.
    #[inline(never)]
    pub(super) fn rounded_t(&self) -> Option<f32> {
        // t = a·n / d·n with n = (b − a) × (c − a); a·n = a·(b×c).
        let den = triple(
            |k| self.d(k),
            |k| self.edge(0, 1, k),
            |k| self.edge(0, 2, k),
        );
        if den.is_zero() {
            return None;
        }
        let num = triple(|k| self.rel(0, k), |k| self.rel(1, k), |k| self.rel(2, k));
        if num.is_zero() {
            return Some(0.0);
        }
        let ((nm, ne), (dm, de)) = (num.approx(), den.approx());
        let mut r = ldexp(nm / dm, 64 * (ne - de)) as f32;
        // `N/D` compared with `m` (a multiple of 2^-150): N·sgn(D)·2^150 against k·|D|.
        let mut num = num;
        let mut den = den;
        if den.neg {
            num.neg = !num.neg;
            den.neg = false;
        }
        let lhs: Wide = num.shl(150);
        let cmp = |m: f64| -> Ordering {
            let k = scaled_integer(m, 150);
            // lhs is below 2^989; a product of 2^1023 or more is certainly larger in magnitude.
            if den.bit_len() + k.bit_len() > 1023 {
                return if k.neg {
                    Ordering::Greater
                } else {
                    Ordering::Less
                };
            }
            let rhs: Wide = den.mul(&k);
            lhs.cmp_signed(&rhs)
        };
        // The estimate is within a few f64 ulps: at most a step or two to the nearest f32.
        for _ in 0..8 {
            if r.is_infinite() {
                // Halfway between f32::MAX and 2^128 (f32::MAX + half its ulp of 2^104): from there
                // on, rounding gives infinity (a tie goes to the even 2^128).
                let edge = f64::from(f32::MAX) + ldexp(1.0, 103);
                let beyond = if r > 0.0 {
                    cmp(edge) != Ordering::Less
                } else {
                    cmp(-edge) != Ordering::Greater
                };
                if beyond {
                    return Some(r);
                }
                r = if r > 0.0 { f32::MAX } else { -f32::MAX };
                continue;
            }
            let up = next_up(r);
            let mid_up = if up.is_finite() {
                0.5 * (f64::from(r) + f64::from(up))
            } else {
                f64::from(r) + 0.5 * (f64::from(r) - f64::from(next_down(r)))
            };
            match cmp(mid_up) {
                Ordering::Greater => {
                    r = up;
                    continue;
                }
                Ordering::Equal if r.to_bits() & 1 == 1 => {
                    r = up;
                    continue;
                }
                _ => {}
            }
            let down = next_down(r);
            let mid_down = if down.is_finite() {
                0.5 * (f64::from(r) + f64::from(down))
            } else {
                f64::from(r) - 0.5 * (f64::from(next_up(r)) - f64::from(r))
            };
            match cmp(mid_down) {
                Ordering::Less => {
                    r = down;
                    continue;
                }
                Ordering::Equal if r.to_bits() & 1 == 1 => {
                    r = down;
                    continue;
                }
                _ => {}
            }
            break;
        }
        Some(if r == 0.0 { 0.0 } else { r })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::workload::SplitMix64;

    fn to_i128(x: &Wide) -> Option<i128> {
        if x.mag[2..].iter().any(|&l| l != 0) || x.mag[1] >> 63 != 0 {
            return None;
        }
        let m = (i128::from(x.mag[1]) << 64) | i128::from(x.mag[0]);
        Some(if x.neg { -m } else { m })
    }

    #[test]
    fn integer_arithmetic_matches_i128() {
        let mut rng = SplitMix64::new(11);
        for _ in 0..20_000 {
            let a = (rng.next_u64() >> 20) as i64 - (1 << 43);
            let b = (rng.next_u64() >> 20) as i64 - (1 << 43);
            let ia = Coord::from_parts(a < 0, a.unsigned_abs(), 0);
            let ib = Coord::from_parts(b < 0, b.unsigned_abs(), 0);
            let mut sum: Wide = ia.shl(0);
            sum.add_assign(&ib);
            let mut diff: Wide = ia.shl(0);
            diff.sub_assign(&ib);
            let prod: Wide = ia.mul(&ib);
            assert_eq!(sum.cmp_signed(&diff), ib.signum().cmp(&0));
            assert_eq!(to_i128(&sum), Some(i128::from(a) + i128::from(b)));
            assert_eq!(to_i128(&diff), Some(i128::from(a) - i128::from(b)));
            assert_eq!(to_i128(&prod), Some(i128::from(a) * i128::from(b)));
            let s = (rng.next_u64() % 40) as u32;
            assert_eq!(
                to_i128(&prod.shl::<16>(s)),
                Some((i128::from(a) * i128::from(b)) << s)
            );
        }
    }

    #[test]
    fn f32_to_integer_is_exact() {
        for x in [
            1.0f32,
            -1.0,
            0.5,
            f32::MIN_POSITIVE,
            f32::from_bits(1),
            3.0,
            -1.5e-40,
        ] {
            let c = Coord::from_f32(x);
            // Back: the integer times 2^-149.
            let (m, e) = c.approx();
            let back = ldexp(m, 64 * e - 149);
            assert_eq!(back, f64::from(x), "{x}");
        }
        let big = Coord::from_f32(f32::MAX);
        let (m, e) = big.approx();
        assert_eq!(ldexp(m, 64 * e - 149), f64::from(f32::MAX));
    }

    /// `p/q` (`q > 0`, small) compared exactly with the f64 `m`.
    fn cmp_rational(p: i128, q: i128, m: f64) -> Ordering {
        let raw = m.to_bits();
        let exp = ((raw >> 52) & 0x7ff) as i32;
        let frac = i128::from(raw & ((1u64 << 52) - 1));
        let (mut mm, e) = if exp == 0 {
            (frac, -1074)
        } else {
            (frac | (1 << 52), exp - 1075)
        };
        if raw >> 63 != 0 {
            mm = -mm;
        }
        // Drop trailing zeros so the shifts below stay small.
        let (mut mm, mut e) = (mm, e);
        while mm != 0 && mm % 2 == 0 {
            mm /= 2;
            e += 1;
        }
        if e >= 0 {
            p.cmp(&((mm * q) << e))
        } else {
            (p << -e).cmp(&(mm * q))
        }
    }

    /// `p/q` (`q > 0`, small integers) rounded to the nearest f32, ties to even: the oracle for
    /// `rounded_t`, by exact comparisons with the midpoints around an f64 estimate.
    fn round_rational(p: i128, q: i128) -> f32 {
        let mut r = (p as f64 / q as f64) as f32;
        loop {
            let up = next_up(r);
            let c = cmp_rational(p, q, 0.5 * (f64::from(r) + f64::from(up)));
            if c == Ordering::Greater || (c == Ordering::Equal && r.to_bits() & 1 == 1) {
                r = up;
                continue;
            }
            let down = next_down(r);
            let c = cmp_rational(p, q, 0.5 * (f64::from(r) + f64::from(down)));
            if c == Ordering::Less || (c == Ordering::Equal && r.to_bits() & 1 == 1) {
                r = down;
                continue;
            }
            return r;
        }
    }

    #[test]
    fn edge_signs_and_t_on_integer_triangles() {
        // Small integer coordinates: every triple product fits i128 and is exact in f64 too.
        let mut rng = SplitMix64::new(5);
        let mut r = || (rng.below(41) as f32) - 20.0;
        for _ in 0..20_000 {
            let tri = [
                Vec3::new(r(), r(), r()),
                Vec3::new(r(), r(), r()),
                Vec3::new(r(), r(), r()),
            ];
            let org = Vec3::new(r(), r(), r());
            let dir = Vec3::new(r(), r(), r());
            let e = ExactTriangle::new(org, dir, &tri);
            let i = |v: Vec3| [v.x as i128, v.y as i128, v.z as i128];
            let (a, b, c, d) = (i(tri[0] - org), i(tri[1] - org), i(tri[2] - org), i(dir));
            let cr = |p: [i128; 3], q: [i128; 3]| {
                [
                    p[1] * q[2] - p[2] * q[1],
                    p[2] * q[0] - p[0] * q[2],
                    p[0] * q[1] - p[1] * q[0],
                ]
            };
            let dt = |p: [i128; 3], q: [i128; 3]| p[0] * q[0] + p[1] * q[1] + p[2] * q[2];
            let want = [
                dt(d, cr(c, b)).signum(),
                dt(d, cr(a, c)).signum(),
                dt(d, cr(b, a)).signum(),
            ];
            for (k, &w) in want.iter().enumerate() {
                assert_eq!(i128::from(e.edge_sign(k)), w);
            }
            let ba = [b[0] - a[0], b[1] - a[1], b[2] - a[2]];
            let ca = [c[0] - a[0], c[1] - a[1], c[2] - a[2]];
            let den = dt(d, cr(ba, ca));
            let num = dt(a, cr(b, c));
            let got = e.rounded_t();
            if den == 0 {
                assert_eq!(got, None);
            } else {
                let (p, q) = if den < 0 { (-num, -den) } else { (num, den) };
                let want = if p == 0 { 0.0 } else { round_rational(p, q) };
                assert_eq!(got.map(f32::to_bits), Some(want.to_bits()), "{num}/{den}");
            }
        }
    }
}
