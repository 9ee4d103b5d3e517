//! The triangle test against its definition: the exact integer answer, on random and adversarial
//! ray/triangle pairs; the four-wide filter never rejects a hit; the list test equals the scalar one.

use alloc::vec::Vec;
use glam::Vec3;

use super::exact::ExactTriangle;
use super::lanes::{Lanes, Portable, Watched, F4, TINY_RESULTS};
use super::testgen::{log_uniform, pair, point, signed};
use super::{filter, Block4, PreparedRay};
use crate::ray::{Aabb, Ray};
use crate::workload::SplitMix64;

/// The definition, computed in exact integers throughout: the line meets the closed triangle (exact
/// edge signs, not mixed, not all zero), `t` rounded to nearest, in the window and finite.
fn definition(ray: &Ray, tri: &[Vec3; 3]) -> Option<f32> {
    let r = PreparedRay::new(ray)?;
    if !tri.iter().all(|p| p.is_finite()) {
        return None;
    }
    let e = ExactTriangle::new(r.org, r.dir, tri);
    let s = [e.edge_sign(0), e.edge_sign(1), e.edge_sign(2)];
    let pos = s.iter().any(|&x| x > 0);
    let neg = s.iter().any(|&x| x < 0);
    if pos == neg {
        return None;
    }
    let t = e.rounded_t()?;
    (t.is_finite() && t >= r.tmin && t <= r.tmax).then_some(t)
}

/// Checks the production test against the definition on one pair: the same decision and the same
/// `t` bits; barycentrics close to the exact ones and in `[0, 1]`. Returns the answer.
fn check(ray: &Ray, tri: &[Vec3; 3]) -> Option<f32> {
    let want = definition(ray, tri);
    let got = PreparedRay::new(ray).and_then(|r| r.intersect_triangle(tri[0], tri[1], tri[2]));
    assert_eq!(
        got.map(|h| h.0.to_bits()),
        want.map(f32::to_bits),
        "ray {ray:?} triangle {tri:?}: got {got:?}, want t = {want:?}"
    );
    if let (Some((_, u, v)), Some(_)) = (got, want) {
        let r = PreparedRay::new(ray).unwrap();
        let (eu, ev) = ExactTriangle::new(r.org, r.dir, tri).barycentrics();
        for (x, ex) in [(u, eu), (v, ev)] {
            assert!(
                (0.0..=1.0).contains(&x),
                "{x} outside [0, 1]: {ray:?} {tri:?}"
            );
            assert!(
                (x - ex).abs() <= 1e-6,
                "barycentric {x} vs exact {ex}: {ray:?} {tri:?}"
            );
        }
    }
    want
}

#[test]
fn the_test_gives_the_exact_answer() {
    use core::sync::atomic::Ordering::Relaxed;
    let (edges0, t0) = (super::COLD_EDGES.load(Relaxed), super::COLD_T.load(Relaxed));
    let mut rng = SplitMix64::new(0x7e57);
    let (mut hits, mut misses, mut windows) = (0usize, 0usize, 0usize);
    for case in 0..300_000 {
        let (ray, tri) = pair(&mut rng, case);
        match check(&ray, &tri) {
            Some(t) => {
                hits += 1;
                // Windows that start or end exactly at the hit, or just past it.
                for (lo, hi) in [
                    (t, t),
                    (t, f32::INFINITY),
                    (0.0, t),
                    (f32::from_bits(t.to_bits() + 1), f32::INFINITY),
                    (-f32::INFINITY, t * 0.999_999_9),
                ] {
                    check(&Ray::segment(ray.org, ray.dir, lo, hi), &tri);
                    windows += 1;
                }
            }
            None => misses += 1,
        }
    }
    assert!(
        hits > 50_000 && misses > 50_000 && windows > 0,
        "{hits} hits, {misses} misses"
    );
    // The pairs reach the exact stage often enough for the comparison to cover it.
    let edges = super::COLD_EDGES.load(Relaxed) - edges0;
    let t = super::COLD_T.load(Relaxed) - t0;
    assert!(
        edges > 1_000 && t > 100,
        "exact stage reached {edges} times for edges, {t} for t"
    );
}

#[test]
fn rays_through_shared_vertices_and_edges_hit_a_neighbour() {
    // A fan of triangles around a vertex and a strip sharing edges, with integer coordinates: rays
    // aimed exactly at the shared vertex and edge midpoints must hit at least one of them.
    let c = Vec3::new(0.0, 0.0, 0.0);
    let ring: [Vec3; 6] = core::array::from_fn(|k| {
        let a = k as f32 * core::f32::consts::TAU / 6.0;
        Vec3::new(
            crate::math::cos(a) * 4.0,
            crate::math::sin(a) * 4.0,
            (k % 2) as f32,
        )
    });
    let fan: [[Vec3; 3]; 6] = core::array::from_fn(|k| [c, ring[k], ring[(k + 1) % 6]]);
    let mut rng = SplitMix64::new(3);
    for _ in 0..20_000 {
        let k = rng.below(6);
        let aim = match rng.below(3) {
            0 => c,
            1 => ring[k],
            _ => 0.5 * (c + ring[k]),
        };
        let mut org = point(&mut rng) * 10.0;
        org.z = 5.0 + rng.next_f32() * 5.0;
        let ray = Ray::new(org, aim - org);
        let hit = fan.iter().any(|tri| check(&ray, tri).is_some());
        // The fan is a height field over the hexagon seen from above: a ray descending to its inner
        // vertex or to a spoke's midpoint meets it there or before. (Rays at the outer vertices may
        // graze the rim and are only checked against the definition.)
        if aim != ring[k] {
            assert!(hit, "ray {ray:?} slipped through the fan");
        }
    }
}

#[test]
fn rays_that_cannot_hit_are_refused() {
    let tri = [Vec3::ZERO, Vec3::X, Vec3::Y];
    for ray in [
        Ray::new(Vec3::new(0.2, 0.2, 1.0), Vec3::ZERO),
        Ray::new(Vec3::new(f32::NAN, 0.2, 1.0), -Vec3::Z),
        Ray::new(
            Vec3::new(0.2, 0.2, 1.0),
            Vec3::new(0.0, f32::INFINITY, -1.0),
        ),
        Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 2.0, 1.0),
        Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, f32::NAN, 1.0),
    ] {
        assert!(PreparedRay::new(&ray).is_none(), "{ray:?}");
    }
    // An empty window at infinity is a valid ray that hits nothing (hits have a finite t).
    let at_infinity = Ray::segment(
        Vec3::new(0.2, 0.2, 1.0),
        -Vec3::Z,
        f32::INFINITY,
        f32::INFINITY,
    );
    assert_eq!(check(&at_infinity, &tri), None);
    let r = PreparedRay::new(&Ray::new(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z)).unwrap();
    assert!(r.intersect_triangle(tri[0], tri[1], tri[2]).is_some());
    for bad in [f32::NAN, f32::INFINITY] {
        assert!(r
            .intersect_triangle(Vec3::ZERO, Vec3::new(bad, 0.0, 0.0), Vec3::Y)
            .is_none());
    }
    // A window exactly at the hit, and one ulp short of it.
    let one = Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 1.0, 1.0);
    assert_eq!(check(&one, &tri), Some(1.0));
    let short = Ray::segment(Vec3::new(0.2, 0.2, 1.0), -Vec3::Z, 0.0, 0.999_999_94);
    assert_eq!(check(&short, &tri), None);
    // Edge-on: the ray lies in the triangle's plane.
    let edge_on = Ray::new(Vec3::new(-1.0, 0.2, 0.0), Vec3::X);
    assert_eq!(check(&edge_on, &tri), None);
    // Crossing beyond the f32 range: a miss.
    let far = Ray::new(Vec3::new(0.2, 0.2, 3e38), Vec3::new(0.0, 0.0, -1e-3));
    assert_eq!(check(&far, &tri), None);
}

/// The lanes of `block` the query's filter lets through for `r` (through the kernel, as queries
/// run it).
fn kernel_survivors(r: &PreparedRay, block: &Block4) -> u32 {
    use super::{Kernel, TriangleTest};
    match r.axes {
        0 => Kernel::<0, false>::new(r, None).survivors(block),
        1 => Kernel::<0, true>::new(r, None).survivors(block),
        2 => Kernel::<1, false>::new(r, None).survivors(block),
        3 => Kernel::<1, true>::new(r, None).survivors(block),
        4 => Kernel::<2, false>::new(r, None).survivors(block),
        _ => Kernel::<2, true>::new(r, None).survivors(block),
    }
}

/// The scene's bound, the filter's first check, never rejects a hit: each block's scene is the box
/// of its own triangle (in every lane, its vertices rotated), so that the scene's bound is as tight
/// as it gets. (A scene bound cut to 1/100 fails this test.)
#[test]
fn the_scene_bound_never_rejects_a_hit() {
    let mut rng = SplitMix64::new(0x5b);
    let mut checked = 0u32;
    for case in 0..100_000 {
        let (ray, tri) = pair(&mut rng, case);
        let mut block = Block4::default();
        for lane in 0..4 {
            let rotated = [tri[lane % 3], tri[(lane + 1) % 3], tri[(lane + 2) % 3]];
            block.set(lane, &rotated);
        }
        let Some(r) = PreparedRay::prepare(&ray, &Aabb::of_triangle(&tri)) else {
            continue;
        };
        if !r.filter_ok {
            continue;
        }
        checked += 1;
        let hits = hit_lanes(&ray, &block);
        assert_eq!(
            hits & !kernel_survivors(&r, &block),
            0,
            "filter rejected a hit: {ray:?} {tri:?}"
        );
    }
    assert!(checked > 50_000, "{checked}");
}

/// The lanes the exact test hits, for the four triangles of `block`.
fn hit_lanes(ray: &Ray, block: &Block4) -> u32 {
    (0..4).fold(0, |m, k| {
        m | (u32::from(definition(ray, &block.get(k)).is_some()) << k)
    })
}

#[test]
fn the_filter_never_rejects_a_hit_and_rejects_clear_misses() {
    let mut rng = SplitMix64::new(0xf1);
    for case in 0..100_000 {
        let (ray, tri) = pair(&mut rng, case);
        let mut block = Block4::default();
        // The pair's triangle, a random one near it and two from other pairs' scales.
        block.set(0, &tri);
        for lane in 1..4 {
            let (_, other) = pair(&mut rng, case + lane);
            block.set(lane, &other);
        }
        let Some(r) = PreparedRay::new(&ray) else {
            continue;
        };
        let scale = (0..4)
            .flat_map(|k| block.get(k))
            .fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        let r = r.for_scene(scale);
        if !r.filter_ok {
            continue;
        }
        let (vector, plain) = (
            filter_lanes::<F4>(&r, &block),
            filter_lanes::<Portable>(&r, &block),
        );
        assert_eq!(vector, plain, "vector and portable lanes differ: {ray:?}");
        let hits = hit_lanes(&ray, &block);
        assert_eq!(
            hits & !vector,
            0,
            "filter rejected a hit: {ray:?} {block:?}"
        );
    }
    // A filter that rejected nothing would pass the check above: it must also do its job. Random
    // rays against random unit triangles are almost all misses, most of them clear.
    let (mut rejected, mut misses) = (0u32, 0u32);
    for _ in 0..20_000 {
        let ray = Ray::new(point(&mut rng) * 2.0, point(&mut rng));
        let mut block = Block4::default();
        for lane in 0..4 {
            block.set(lane, &[point(&mut rng), point(&mut rng), point(&mut rng)]);
        }
        let Some(r) = PreparedRay::new(&ray) else {
            continue;
        };
        let survivors = kernel_survivors(&r.for_scene(1.0), &block);
        let hits = hit_lanes(&ray, &block);
        assert_eq!(
            hits & !survivors,
            0,
            "filter rejected a hit: {ray:?} {block:?}"
        );
        misses += 4 - hits.count_ones();
        rejected += 4 - survivors.count_ones();
    }
    assert!(
        f64::from(rejected) > 0.95 * f64::from(misses),
        "rejected {rejected} of {misses} misses"
    );
}

/// Two blocks filtered in eight lanes keep exactly the lanes of two four-lane calls, on rays with
/// windows (so that the window check runs in eight lanes too) and blocks of different scales side
/// by side, the scene being the box around both (as every structure's is).
#[test]
fn two_blocks_in_eight_lanes_filter_as_two_calls() {
    if !avx_pair_is_checked() {
        return;
    }
    let mut rng = SplitMix64::new(0x8a1e5);
    let ends = [
        f32::NEG_INFINITY,
        -1.0,
        0.0,
        1e-4,
        0.3,
        0.9,
        1.0,
        1.1,
        3.0,
        f32::INFINITY,
    ];
    let (mut checked, mut windowed, mut kept) = (0u32, 0u32, 0u32);
    for case in 0..100_000 {
        let (ray, tri) = pair(&mut rng, case);
        let (mut a, mut b) = (Block4::default(), Block4::default());
        a.set(0, &tri);
        for lane in 1..4 {
            a.set(lane, &pair(&mut rng, case + lane).1);
        }
        // The other block: 0 to 4 triangles (unused lanes are NaN) of other scales.
        for lane in 0..rng.below(5) {
            let other = case + 1 + rng.below(7);
            b.set(lane, &pair(&mut rng, other).1);
        }
        let (t0, t1) = (ends[rng.below(ends.len())], ends[rng.below(ends.len())]);
        let ray = Ray::segment(ray.org, ray.dir, t0.min(t1), t0.max(t1));
        let Some(r) = PreparedRay::new(&ray) else {
            continue;
        };
        let scale = [&a, &b]
            .iter()
            .flat_map(|block| (0..4).flat_map(|k| block.get(k)))
            .filter(|p| p.is_finite())
            .fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        let r = r.for_scene(scale);
        let Some(pair_of) = avx_pair(&r).filter(|_| r.filter_ok) else {
            continue;
        };
        let (fa, fb) = (filter_lanes::<F4>(&r, &a), filter_lanes::<F4>(&r, &b));
        assert_eq!(pair_of(&a, &b), fa | fb << 4, "{ray:?} {a:?} {b:?}");
        assert_eq!(pair_of(&b, &a), fb | fa << 4, "{ray:?} {a:?} {b:?}");
        checked += 1;
        windowed += u32::from(!(ray.tmin <= 0.0 && ray.tmax == f32::INFINITY));
        kept += (fa | fb << 4).count_ones();
    }
    // Most cases ran, most of them with the window check, and the filter kept lanes in some.
    assert!(
        checked > 30_000 && windowed > 25_000 && kept > 20_000,
        "{checked} {windowed} {kept}"
    );
}

/// Every lane operation the filter uses on `x` and `y`, each result as its lanes' bits (`values`
/// reads the lanes; comparisons as one 0/1 per lane, of `lanes`).
#[cfg(all(target_arch = "x86_64", feature = "avx"))]
#[inline(always)]
fn every_operation<L: Lanes>(
    x: L,
    y: L,
    values: impl Fn(L) -> Vec<f32>,
    lanes: u32,
) -> Vec<Vec<u32>> {
    let bits = |v: L| values(v).iter().map(|f| f.to_bits()).collect::<Vec<u32>>();
    let mask = |m: L::Mask| {
        (0..lanes)
            .map(|k| (L::bits(m) >> k) & 1)
            .collect::<Vec<u32>>()
    };
    alloc::vec![
        bits(x.add(y)),
        bits(x.sub(y)),
        bits(x.mul(y)),
        bits(x.div(y)),
        bits(x.max(y)),
        bits(x.min(y)),
        bits(x.abs()),
        bits(x.neg()),
        mask(x.nle(y)),
        mask(x.nge(y)),
        mask(x.gt(y)),
        mask(x.lt(y)),
    ]
}

/// Each operation of the eight AVX lanes gives, lane for lane, the bits of two calls of the
/// four-lane one, on values of every kind (zeros of both signs, subnormals, infinities, NaN).
#[test]
fn eight_lanes_do_what_two_four_lane_calls_do() {
    #[cfg(all(target_arch = "x86_64", feature = "avx"))]
    {
        use super::lanes::avx::Avx;
        if !avx_pair_is_checked() {
            return;
        }
        /// The eight-lane results and the two four-lane calls' of every operation, as bits.
        /// # Safety
        /// The processor runs AVX.
        #[target_feature(enable = "avx")]
        unsafe fn both(a: [f32; 8], b: [f32; 8]) -> (Vec<Vec<u32>>, Vec<Vec<u32>>) {
            let half =
                |x: &[f32; 8], h: usize| [x[4 * h], x[4 * h + 1], x[4 * h + 2], x[4 * h + 3]];
            let (va, vb) = (
                Avx::load_pair(&half(&a, 0), &half(&a, 1)),
                Avx::load_pair(&half(&b, 0), &half(&b, 1)),
            );
            let eight = every_operation(va, vb, |v: Avx| v.to_array().to_vec(), 8);
            let four = |h: usize| {
                let (x, y) = (F4::load(&half(&a, h)), F4::load(&half(&b, h)));
                every_operation(x, y, |v: F4| v.to_array().to_vec(), 4)
            };
            let (lo, hi) = (four(0), four(1));
            let two = lo.iter().zip(&hi).map(|(l, h)| [&l[..], &h[..]].concat());
            (eight, two.collect())
        }
        /// `Lanes::all` of masks with and without every lane set, against its definition (all
        /// bits of `bits`), for eight lanes and for four.
        /// # Safety
        /// The processor runs AVX.
        #[target_feature(enable = "avx")]
        unsafe fn all_lanes(a: [f32; 8], b: [f32; 8]) -> u32 {
            let half =
                |x: &[f32; 8], h: usize| [x[4 * h], x[4 * h + 1], x[4 * h + 2], x[4 * h + 3]];
            let (va, vb) = (
                Avx::load_pair(&half(&a, 0), &half(&a, 1)),
                Avx::load_pair(&half(&b, 0), &half(&b, 1)),
            );
            let mut all_set = 0;
            for m in [va.nle(vb), va.nle(Avx::splat(f32::NEG_INFINITY)), va.gt(va)] {
                assert_eq!(Avx::all(m), Avx::bits(m) == 0xff, "{a:?} {b:?}");
                all_set += u32::from(Avx::all(m));
            }
            let x = F4::load(&half(&a, 0));
            for m in [
                x.nle(F4::load(&half(&b, 0))),
                x.nle(F4::splat(f32::NEG_INFINITY)),
            ] {
                assert_eq!(F4::all(m), F4::bits(m) == 0b1111, "{a:?} {b:?}");
            }
            all_set
        }
        let special = [
            0.0f32,
            -0.0,
            1.0,
            -1.5,
            1e-45,
            -3e-39,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
            f32::from_bits(0xffc0_0001),
        ];
        let mut rng = SplitMix64::new(0xa1a5);
        let mut all_set = 0;
        for _ in 0..50_000 {
            let mut value = || {
                if rng.below(2) == 0 {
                    special[rng.below(special.len())]
                } else {
                    f32::from_bits(rng.next_u64() as u32)
                }
            };
            let a: [f32; 8] = core::array::from_fn(|_| value());
            let b: [f32; 8] = core::array::from_fn(|_| value());
            // SAFETY: `avx_pair_is_checked` asked the processor.
            let (wide, two) = unsafe { both(a, b) };
            assert_eq!(wide, two, "{a:?} {b:?}");
            // SAFETY: as above.
            all_set += unsafe { all_lanes(a, b) };
        }
        // Masks with every lane set were among them.
        assert!(all_set > 1_000, "{all_set}");
    }
}

/// Whether this build and processor filter blocks in pairs (so the tests must check them).
fn avx_pair_is_checked() -> bool {
    #[cfg(all(target_arch = "x86_64", feature = "avx"))]
    {
        super::lanes::avx::available()
    }
    #[cfg(not(all(target_arch = "x86_64", feature = "avx")))]
    {
        false
    }
}

/// The eight-lane filter of two blocks for `r`, through the kernel the AVX walks use, where this
/// build and processor have it.
#[allow(clippy::type_complexity)]
fn avx_pair(r: &PreparedRay) -> Option<impl Fn(&Block4, &Block4) -> u32 + '_> {
    #[cfg(all(target_arch = "x86_64", feature = "avx"))]
    {
        if !avx_pair_is_checked() {
            return None;
        }
        /// # Safety
        /// The processor runs AVX.
        #[target_feature(enable = "avx")]
        unsafe fn with_avx(r: &PreparedRay, a: &Block4, b: &Block4) -> u32 {
            use super::{Kernel, KernelAvx, TriangleTest};
            macro_rules! pair {
                ($kz:expr, $swap:expr) => {
                    KernelAvx::<$kz, $swap>(
                        Kernel::<$kz, $swap>::new(r, None),
                        filter::FilterRay::new::<$kz, $swap>(r),
                    )
                    .survivors_pair(a, b)
                };
            }
            with_axes!(r, pair)
        }
        // SAFETY: `avx_pair_is_checked` asked the processor.
        Some(move |a: &Block4, b: &Block4| unsafe { with_avx(r, a, b) })
    }
    #[cfg(not(all(target_arch = "x86_64", feature = "avx")))]
    {
        let _ = r;
        None::<fn(&Block4, &Block4) -> u32>
    }
}

/// The float after `x` (`x` finite).
fn next_up(x: f32) -> f32 {
    if x == 0.0 {
        f32::from_bits(1)
    } else if x > 0.0 {
        f32::from_bits(x.to_bits() + 1)
    } else {
        f32::from_bits(x.to_bits() - 1)
    }
}

/// The float before `x` (`x` finite).
fn next_down(x: f32) -> f32 {
    -next_up(-x)
}

/// The window check never rejects a hit: each pair's exact crossing `t` (the window wide open)
/// with windows whose ends sit on `t`, one float beyond it, a little way off and on either side of
/// zero; the vector and portable lanes agree throughout; half of the pairs at other scales. (The
/// check's error term cut to 1/100 fails it, and so does the first version's numerator without a
/// floor; cut to 1/16 it still passes: the bound is a worst case, about ten times what these pairs
/// show.)
#[test]
fn the_window_check_never_rejects_a_hit() {
    let mut rng = SplitMix64::new(0x3d);
    let mut windows_checked = 0u32;
    for case in 0..60_000 {
        let (ray, tri) = pair(&mut rng, case);
        // Half of the pairs moved to another scale by powers of two (exact unless they leave the
        // normal range), their direction to another length: the scales between the pairs' own
        // (1 and 1e-20) are where a numerator that underflows matters.
        let (ray, tri) = if case % 2 == 0 {
            (ray, tri)
        } else {
            let pow2 = |k: i32| 2f32.powi(k);
            let (f, g) = (
                pow2(rng.below(200) as i32 - 100),
                pow2(rng.below(200) as i32 - 100),
            );
            (
                Ray::segment(ray.org * f, ray.dir * g, ray.tmin, ray.tmax),
                tri.map(|p| p * f),
            )
        };
        if !(ray.org.is_finite() && ray.dir.is_finite() && tri.iter().all(|p| p.is_finite())) {
            continue;
        }
        let open = Ray::segment(ray.org, ray.dir, f32::NEG_INFINITY, f32::INFINITY);
        let Some(t) = definition(&open, &tri) else {
            continue;
        };
        let mut block = Block4::default();
        block.set(0, &tri);
        for lane in 1..4 {
            let rotated = [tri[lane % 3], tri[(lane + 1) % 3], tri[(lane + 2) % 3]];
            block.set(lane, &rotated);
        }
        let scale = tri.iter().fold(0.0f32, |m, p| m.max(p.abs().max_element()));
        let near = t.abs() * 1e-6 + 1e-30;
        let windows = [
            (t, t),
            (t, f32::INFINITY),
            (f32::NEG_INFINITY, t),
            (next_up(t), f32::INFINITY),
            (f32::NEG_INFINITY, next_down(t)),
            (t - near, t + near),
            (t + near, t + 2.0 * near),
            (0.0, t),
            (-0.0, f32::INFINITY),
            (t.min(0.0), t.max(0.0)),
        ];
        for (tmin, tmax) in windows {
            if !(tmin <= tmax) || !tmin.is_finite() && !tmax.is_finite() && tmin == tmax {
                continue;
            }
            let windowed = Ray::segment(ray.org, ray.dir, tmin, tmax);
            let Some(r) = PreparedRay::new(&windowed) else {
                continue;
            };
            let r = r.for_scene(scale);
            if !r.filter_ok {
                continue;
            }
            windows_checked += 1;
            let survivors = kernel_survivors(&r, &block);
            assert_eq!(survivors, filter_lanes::<Portable>(&r, &block));
            let hits = hit_lanes(&windowed, &block);
            assert_eq!(
                hits & !survivors,
                0,
                "window check rejected a hit: {windowed:?} {tri:?} (t = {t})"
            );
        }
    }
    assert!(windows_checked > 150_000, "{windows_checked}");
}

/// A tiny triangle near the origin: the window check's numerator underflows, and a small
/// determinant magnifies what it loses (a review's counterexample to the first version).
#[test]
fn a_tiny_triangle_near_the_origin_keeps_its_hit() {
    for (s, z) in [
        (3e-14f32, 3e-14f32),
        (1e-13, 1e-15),
        (3e-11, 1e-20),
        (2e-12, 1e-18),
    ] {
        let tri = [
            Vec3::new(-s, -0.7 * s, z),
            Vec3::new(1.3 * s, -s, 1.1 * z),
            Vec3::new(0.1 * s, s, 0.9 * z),
        ];
        let open = Ray::segment(Vec3::ZERO, Vec3::Z, f32::NEG_INFINITY, f32::INFINITY);
        let t = definition(&open, &tri).expect("the line meets the triangle");
        for (tmin, tmax) in [(t, f32::INFINITY), (t, t), (0.5 * t, 2.0 * t)] {
            let ray = Ray::segment(Vec3::ZERO, Vec3::Z, tmin, tmax);
            assert!(definition(&ray, &tri).is_some());
            let mut block = Block4::default();
            block.set(0, &tri);
            let r = PreparedRay::new(&ray).unwrap().for_scene(2.0 * s.max(z));
            assert!(r.filter_ok);
            assert_eq!(
                kernel_survivors(&r, &block) & 1,
                1,
                "s = {s:e}, z = {z:e}, window [{tmin:e}, {tmax:e}]"
            );
        }
    }
}

/// The window check does its job: a ray leaving a triangle (its origin a point of the triangle,
/// rounded, `tmin` a small offset, as renderers trace bounces) does not send that triangle to the
/// exact test, nor a triangle wholly behind the origin or beyond `tmax`, although each passes the
/// edge test (the line meets it). (Without the check, each count below is 0.)
#[test]
fn the_window_check_rejects_crossings_outside_the_window() {
    let mut rng = SplitMix64::new(0x77);
    let (mut own, mut behind, mut beyond, mut lines) = (0u32, 0u32, 0u32, 0u32);
    for _ in 0..5_000 {
        let tri = [point(&mut rng), point(&mut rng), point(&mut rng)];
        let n = (tri[1] - tri[0]).cross(tri[2] - tri[0]);
        if n.length() < 0.1 {
            continue;
        }
        let b = [
            rng.next_f32() + 0.05,
            rng.next_f32() + 0.05,
            rng.next_f32() + 0.05,
        ];
        let sum = b[0] + b[1] + b[2];
        let on = (b[0] * tri[0] + b[1] * tri[1] + b[2] * tri[2]) / sum;
        let out = (point(&mut rng).normalize_or(Vec3::X) + 1.5 * n.normalize()).normalize();
        let mut block = Block4::default();
        block.set(0, &tri);
        let lanes = |ray: &Ray| {
            let r = PreparedRay::new(ray).unwrap().for_scene(4.0);
            assert!(r.filter_ok);
            kernel_survivors(&r, &block) & 1
        };
        let bounce = Ray::segment(on, out, 1e-4, f32::INFINITY);
        // (A window `[0, ∞)` skips the check: the window here is finite.)
        let away = Ray::segment(on + out, out, 0.0, 1e3);
        let short = Ray::segment(on - out, out, 0.0, 0.5);
        for ray in [&bounce, &away, &short] {
            let open = Ray::segment(ray.org, ray.dir, f32::NEG_INFINITY, f32::INFINITY);
            lines += u32::from(definition(&open, &tri).is_some());
        }
        own += 1 - lanes(&bounce);
        behind += 1 - lanes(&away);
        beyond += 1 - lanes(&short);
    }
    assert!(lines > 3 * 4_000, "{lines}");
    let tried = lines / 3;
    for (what, n) in [("own", own), ("behind", behind), ("beyond", beyond)] {
        assert!(
            f64::from(n) > 0.99 * f64::from(tried),
            "{what}: {n} of {tried}"
        );
    }
}

/// [`filter::survivors`] for `r` on lanes `L`.
fn filter_lanes<L: Lanes>(r: &PreparedRay, block: &Block4) -> u32 {
    fn with<L: Lanes, const KZ: usize, const SWAP: bool>(r: &PreparedRay, block: &Block4) -> u32 {
        let ray = filter::FilterRay::<L>::new::<KZ, SWAP>(r);
        filter::survivors::<L, KZ, SWAP>(&ray, block)
    }
    match r.axes {
        0 => with::<L, 0, false>(r, block),
        1 => with::<L, 0, true>(r, block),
        2 => with::<L, 1, false>(r, block),
        3 => with::<L, 1, true>(r, block),
        4 => with::<L, 2, false>(r, block),
        _ => with::<L, 2, true>(r, block),
    }
}

#[test]
fn portable_lanes_do_what_the_vector_lanes_do() {
    let mut rng = SplitMix64::new(9);
    for _ in 0..10_000 {
        let a: [f32; 4] =
            core::array::from_fn(|_| signed(&mut rng) * log_uniform(&mut rng, -30.0, 30.0));
        let b: [f32; 4] =
            core::array::from_fn(|_| signed(&mut rng) * log_uniform(&mut rng, -30.0, 30.0));
        let (pa, pb, va, vb) = (
            Portable::load(&a),
            Portable::load(&b),
            F4::load(&a),
            F4::load(&b),
        );
        let same = |p: Portable, v: F4| {
            let (p, v) = (
                Portable::bits(Portable::nge(p, Portable::splat(0.0)))
                    | (Portable::bits(Portable::nle(p, Portable::splat(1.0))) << 4),
                F4::bits(F4::nge(v, F4::splat(0.0))) | (F4::bits(F4::nle(v, F4::splat(1.0))) << 4),
            );
            assert_eq!(p, v);
        };
        same(pa.add(pb), va.add(vb));
        same(pa.sub(pb), va.sub(vb));
        same(pa.mul(pb), va.mul(vb));
        same(pa.max(pb), va.max(vb));
        same(pa.min(pb), va.min(vb));
        same(pa.abs(), va.abs());
        same(pa.neg(), va.neg());
        assert_eq!(Portable::bits(pa.nle(pb)), F4::bits(va.nle(vb)));
        assert_eq!(Portable::bits(pa.nge(pb)), F4::bits(va.nge(vb)));
        assert_eq!(Portable::bits(pa.gt(pb)), F4::bits(va.gt(vb)));
        assert_eq!(Portable::bits(pa.lt(pb)), F4::bits(va.lt(vb)));
        same(pa.div(pb), va.div(vb));
        assert_eq!(
            Portable::bits(Portable::and(pa.nle(pb), pa.nge(pb.neg()))),
            F4::bits(F4::and(va.nle(vb), va.nge(vb.neg())))
        );
    }
    // The negated comparisons hold where a lane is NaN: the filter rejects unused lanes by them.
    let (pn, vn) = (Portable::splat(f32::NAN), F4::splat(f32::NAN));
    let (p0, v0) = (Portable::splat(0.0), F4::splat(0.0));
    assert_eq!(
        Portable::bits(Portable::and(pn.nle(p0), pn.nge(p0))),
        0b1111
    );
    assert_eq!(F4::bits(F4::and(vn.nle(v0), vn.nge(v0))), 0b1111);
    assert_eq!(Portable::bits(Portable::and(p0.nle(p0), p0.nge(p0))), 0);
    assert_eq!(F4::bits(F4::and(v0.nle(v0), v0.nge(v0))), 0);
    // The ordered comparisons do not hold where a lane is NaN: the window check keeps such lanes.
    assert_eq!(Portable::bits(pn.gt(p0)) | Portable::bits(pn.lt(p0)), 0);
    assert_eq!(F4::bits(vn.gt(v0)) | F4::bits(vn.lt(v0)), 0);
}

/// A gathered block holds, lane by lane, what `set` puts there, and NaN where the id names no
/// triangle.
#[test]
fn a_gathered_block_matches_one_set_lane_by_lane() {
    let mut rng = SplitMix64::new(0x6a);
    let tris: Vec<[Vec3; 3]> = (0..16)
        .map(|_| [point(&mut rng), point(&mut rng), point(&mut rng)])
        .collect();
    for ids in [
        [0, 5, 15, 3],
        [7, u32::MAX, 16, 2],
        [u32::MAX; 4],
        [9, 9, 9, 9],
    ] {
        let mut want = Block4::default();
        for (lane, &id) in ids.iter().enumerate() {
            if let Some(tri) = tris.get(id as usize) {
                want.set(lane, tri);
            }
        }
        let got = Block4::gather(&tris, ids);
        for (k, (g, w)) in got.v.iter().zip(&want.v).enumerate() {
            for lane in 0..4 {
                assert!(
                    g[lane] == w[lane] || (g[lane].is_nan() && w[lane].is_nan()),
                    "coordinate {k} lane {lane} of {ids:?}"
                );
            }
        }
    }
}

/// `edge_bound` is at least the derivation's factored bound (`derived_bound`) on values of every
/// magnitude the edge functions can give: zero, subnormal, tiny, huge (up to 2^131), exact powers
/// of two and random mantissas, and `S`, `Z` far apart.
#[test]
fn the_expanded_bound_is_at_least_the_derived_one() {
    let mut rng = SplitMix64::new(0xb0b0);
    let value = |rng: &mut SplitMix64| -> f64 {
        match rng.below(8) {
            0 => 0.0,
            1 => f64::from_bits(rng.next_u64() % (1 << 52)), // subnormal
            2 => 2f64.powi(rng.below(1200) as i32 - 1074),
            _ => {
                let m = 1.0 + (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
                m * 2f64.powi(rng.below(1150) as i32 - 1020)
            }
        }
    };
    for _ in 0..if cfg!(miri) { 1_000 } else { 2_000_000 } {
        let (s, z) = (value(&mut rng), value(&mut rng));
        let (s, z) = (s.min(2f64.powi(131)), z.min(2f64.powi(131)));
        let (expanded, derived) = (super::edge_bound(s, z), super::derived_bound(s, z));
        assert!(
            expanded >= derived && expanded.is_finite(),
            "s {s:e} z {z:e}: expanded {expanded:e} < derived {derived:e}"
        );
    }
}

/// The filter computes nothing subnormal on the rays and triangles of ordinary scenes (coordinates
/// of 10^-2..10^3): camera rays, bounces leaving their own triangle, shadow rays, axis-aligned
/// directions, and bounces from an axis-aligned floor, which start exactly in the plane of the
/// floor's other triangles. A subnormal product there cost stadium scenes 10–20 % of their time
/// per ray until stop 29 (the window check's floor; docs/performance.md), and this test finds it.
#[test]
fn the_filter_makes_no_subnormal_value_on_ordinary_scenes() {
    let mut rng = SplitMix64::new(0x5ab);
    let mut checked = 0;
    for case in 0..20_000 {
        let scale = log_uniform(&mut rng, -2.0, 3.0);
        let floor = case % 2 == 0;
        // A block of four triangles: on the floor `y = 0` (sizes up to the scene's), or anywhere.
        let tris: [[Vec3; 3]; 4] = core::array::from_fn(|_| {
            let p = |rng: &mut SplitMix64| {
                let q = point(rng) * scale;
                if floor {
                    Vec3::new(q.x, 0.0, q.z)
                } else {
                    q
                }
            };
            [p(&mut rng), p(&mut rng), p(&mut rng)]
        });
        let mut block = Block4::default();
        for (lane, tri) in tris.iter().enumerate() {
            block.set(lane, tri);
        }
        // An origin on the first triangle (rounded, as renderers store it), above the scene or
        // on an axis; a direction away from it, or an axis.
        let on = (tris[0][0] + tris[0][1] + tris[0][2]) / 3.0;
        let (org, dir, tmin, tmax) = match rng.below(4) {
            0 => {
                let d = Vec3::new(signed(&mut rng), rng.next_f32() + 0.01, signed(&mut rng));
                (on, d.normalize(), 1e-4 * scale, f32::INFINITY)
            }
            1 => {
                let o = on + Vec3::new(0.0, scale, 0.0) * (1.0 + rng.next_f32());
                (o, (on - o).normalize(), 0.0, f32::INFINITY)
            }
            2 => {
                let d = Vec3::new(signed(&mut rng), rng.next_f32() + 0.01, signed(&mut rng));
                (on, d.normalize(), 1e-4 * scale, scale * rng.next_f32())
            }
            _ => {
                let axis = [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::Y][rng.below(4)];
                (on + 0.5 * scale * Vec3::Y, axis, 0.0, f32::INFINITY)
            }
        };
        let ray = Ray::segment(org, dir, tmin, tmax);
        let Some(r) = PreparedRay::new(&ray) else {
            continue;
        };
        let r = r.for_scene(4.0 * scale);
        TINY_RESULTS.store(0, core::sync::atomic::Ordering::Relaxed);
        filter_lanes::<Watched>(&r, &block);
        let tiny = TINY_RESULTS.load(core::sync::atomic::Ordering::Relaxed);
        assert_eq!(tiny, 0, "case {case}: ray {ray:?} block {tris:?}");
        checked += 1;
    }
    assert!(checked > 19_000, "{checked}");
}

/// The run-time check that picks the AVX walks agrees with the standard library's.
#[test]
#[cfg(all(target_arch = "x86_64", feature = "avx", feature = "std", not(miri)))]
fn avx_detection_agrees_with_std() {
    assert_eq!(
        super::lanes::avx::available(),
        std::is_x86_feature_detected!("avx")
    );
}
