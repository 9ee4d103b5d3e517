//! Four f32 lanes: the few operations the filter needs, on SSE2 (x86, x86-64), NEON (AArch64) or
//! plain arrays elsewhere. Every implementation performs the same IEEE operations lane by lane (no
//! fused multiply-add), so all three give the same bits for the same inputs without NaN.

/// f32 lanes (four; eight for AVX) and their comparison masks.
pub(crate) trait Lanes: Copy {
    /// The number of lanes (four, eight for AVX): `bits` has this many low bits.
    const WIDTH: u32;
    /// The result of a lane-wise comparison.
    type Mask: Copy;
    fn splat(x: f32) -> Self;
    fn load(v: &[f32; 4]) -> Self;
    fn add(self, o: Self) -> Self;
    fn sub(self, o: Self) -> Self;
    fn mul(self, o: Self) -> Self;
    fn div(self, o: Self) -> Self;
    /// The larger of each pair. NaN handling differs between implementations (SSE2 and the plain
    /// version return `o`, NEON returns NaN); the filter meets NaN only in unused lanes, NaN
    /// throughout, which every version rejects (real triangles give no NaN below 2^60).
    fn max(self, o: Self) -> Self;
    /// The smaller of each pair (NaN as for `max`).
    fn min(self, o: Self) -> Self;
    fn abs(self) -> Self;
    fn neg(self) -> Self;
    /// Set where `self > o` or either is NaN (`!(self <= o)`).
    fn nle(self, o: Self) -> Self::Mask;
    /// Set where `self < o` or either is NaN (`!(self >= o)`).
    fn nge(self, o: Self) -> Self::Mask;
    /// Set where `self > o` (clear where either is NaN).
    fn gt(self, o: Self) -> Self::Mask;
    /// Set where `self < o` (clear where either is NaN).
    fn lt(self, o: Self) -> Self::Mask;
    fn and(a: Self::Mask, b: Self::Mask) -> Self::Mask;
    /// Bit `k` set where lane `k` of the mask is set.
    fn bits(m: Self::Mask) -> u32;
    /// Whether every lane of the mask is set, for the filter's first check: every one of `bits`'
    /// `WIDTH` bits. AVX overrides it with one `vtestps`, where the comparison of `bits` with 0xff
    /// compiled to a conversion of the mask to floats and a float comparison before the branch.
    #[inline(always)]
    fn all(m: Self::Mask) -> bool {
        Self::bits(m) == (1 << Self::WIDTH) - 1
    }
}

/// Plain arrays: the reference the vector versions are tested against, and the version for targets
/// without SSE2 or NEON (hence unused in some builds).
#[allow(dead_code)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Portable([f32; 4]);

#[allow(dead_code)]
impl Portable {
    #[inline(always)]
    fn map2(self, o: Self, f: impl Fn(f32, f32) -> f32) -> Self {
        Portable(core::array::from_fn(|k| f(self.0[k], o.0[k])))
    }

    #[inline(always)]
    fn cmp(self, o: Self, f: impl Fn(f32, f32) -> bool) -> u32 {
        (0..4).fold(0, |m, k| m | (u32::from(f(self.0[k], o.0[k])) << k))
    }
}

impl Lanes for Portable {
    const WIDTH: u32 = 4;
    type Mask = u32;
    #[inline(always)]
    fn splat(x: f32) -> Self {
        Portable([x; 4])
    }
    #[inline(always)]
    fn load(v: &[f32; 4]) -> Self {
        Portable(*v)
    }
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        self.map2(o, |a, b| a + b)
    }
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        self.map2(o, |a, b| a - b)
    }
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        self.map2(o, |a, b| a * b)
    }
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        self.map2(o, |a, b| a / b)
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        self.map2(o, |a, b| if a > b { a } else { b })
    }
    #[inline(always)]
    fn min(self, o: Self) -> Self {
        self.map2(o, |a, b| if a < b { a } else { b })
    }
    #[inline(always)]
    fn abs(self) -> Self {
        Portable(self.0.map(|a| f32::from_bits(a.to_bits() & 0x7fff_ffff)))
    }
    #[inline(always)]
    fn neg(self) -> Self {
        Portable(self.0.map(|a| -a))
    }
    #[inline(always)]
    fn nle(self, o: Self) -> u32 {
        self.cmp(o, |a, b| !(a <= b))
    }
    #[inline(always)]
    fn nge(self, o: Self) -> u32 {
        self.cmp(o, |a, b| !(a >= b))
    }
    #[inline(always)]
    fn gt(self, o: Self) -> u32 {
        self.cmp(o, |a, b| a > b)
    }
    #[inline(always)]
    fn lt(self, o: Self) -> u32 {
        self.cmp(o, |a, b| a < b)
    }

    #[inline(always)]
    fn and(a: u32, b: u32) -> u32 {
        a & b
    }
    #[inline(always)]
    fn bits(m: u32) -> u32 {
        m
    }
}

/// Results of [`Watched`] lanes' arithmetic whose exact value is subnormal, counted since the
/// last reset.
#[cfg(test)]
pub(crate) static TINY_RESULTS: core::sync::atomic::AtomicUsize =
    core::sync::atomic::AtomicUsize::new(0);

/// The plain lanes, counting in [`TINY_RESULTS`] every sum, difference, product and quotient whose
/// exact value lies between zero and 2^-126 (which x86 finishes with a microcode assist of ~100
/// cycles unless flush-to-zero is set); the exact value is taken in f64 (exact for `+`, `−`, `×`
/// of f32). For tests that the filter's arithmetic stays normal.
#[cfg(test)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Watched(Portable);

#[cfg(test)]
impl Watched {
    fn watched(
        self,
        o: Self,
        op: impl Fn(f32, f32) -> f32,
        exact: impl Fn(f64, f64) -> f64,
    ) -> Self {
        for k in 0..4 {
            let x = exact(f64::from((self.0).0[k]), f64::from((o.0).0[k]));
            if x != 0.0 && x.abs() < f64::from(f32::MIN_POSITIVE) {
                TINY_RESULTS.fetch_add(1, core::sync::atomic::Ordering::Relaxed);
            }
        }
        Watched(self.0.map2(o.0, op))
    }
}

#[cfg(test)]
impl Lanes for Watched {
    const WIDTH: u32 = 4;
    type Mask = u32;
    fn splat(x: f32) -> Self {
        Watched(Portable::splat(x))
    }
    fn load(v: &[f32; 4]) -> Self {
        Watched(Portable::load(v))
    }
    fn add(self, o: Self) -> Self {
        self.watched(o, |a, b| a + b, |a, b| a + b)
    }
    fn sub(self, o: Self) -> Self {
        self.watched(o, |a, b| a - b, |a, b| a - b)
    }
    fn mul(self, o: Self) -> Self {
        self.watched(o, |a, b| a * b, |a, b| a * b)
    }
    fn div(self, o: Self) -> Self {
        self.watched(o, |a, b| a / b, |a, b| a / b)
    }
    fn max(self, o: Self) -> Self {
        Watched(self.0.max(o.0))
    }
    fn min(self, o: Self) -> Self {
        Watched(self.0.min(o.0))
    }
    fn abs(self) -> Self {
        Watched(self.0.abs())
    }
    fn neg(self) -> Self {
        Watched(self.0.neg())
    }
    fn nle(self, o: Self) -> u32 {
        self.0.nle(o.0)
    }
    fn nge(self, o: Self) -> u32 {
        self.0.nge(o.0)
    }
    fn gt(self, o: Self) -> u32 {
        self.0.gt(o.0)
    }
    fn lt(self, o: Self) -> u32 {
        self.0.lt(o.0)
    }
    fn and(a: u32, b: u32) -> u32 {
        a & b
    }
    fn bits(m: u32) -> u32 {
        m
    }
}

#[cfg(all(
    any(target_arch = "x86", target_arch = "x86_64"),
    target_feature = "sse2"
))]
mod sse2 {
    // The intrinsics are safe to call under `target_feature = "sse2"` in newer compilers and
    // `unsafe` in older ones; the blocks below hold no other operation.
    #![allow(unused_unsafe)]

    #[cfg(target_arch = "x86")]
    use core::arch::x86::*;
    #[cfg(target_arch = "x86_64")]
    use core::arch::x86_64::*;

    use super::Lanes;

    /// Four lanes in an SSE register.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Sse2(__m128);

    #[cfg(test)]
    impl Sse2 {
        /// The four lanes' values.
        pub(crate) fn to_array(self) -> [f32; 4] {
            let mut out = [0.0; 4];
            // SAFETY: `out` is 16 writable bytes; the unaligned store needs no alignment.
            unsafe { _mm_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }
    }

    impl Lanes for Sse2 {
        const WIDTH: u32 = 4;
        type Mask = __m128;
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Sse2(unsafe { _mm_set1_ps(x) })
        }
        #[inline(always)]
        fn load(v: &[f32; 4]) -> Self {
            // SAFETY: `v` is 16 readable bytes; the unaligned load has no alignment requirement.
            Sse2(unsafe { _mm_loadu_ps(v.as_ptr()) })
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Sse2(unsafe { _mm_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Sse2(unsafe { _mm_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Sse2(unsafe { _mm_mul_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Sse2(unsafe { _mm_div_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            Sse2(unsafe { _mm_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            Sse2(unsafe { _mm_min_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn abs(self) -> Self {
            Sse2(unsafe { _mm_and_ps(self.0, _mm_castsi128_ps(_mm_set1_epi32(0x7fff_ffff))) })
        }
        #[inline(always)]
        fn neg(self) -> Self {
            Sse2(unsafe { _mm_xor_ps(self.0, _mm_set1_ps(-0.0)) })
        }
        #[inline(always)]
        fn nle(self, o: Self) -> __m128 {
            unsafe { _mm_cmpnle_ps(self.0, o.0) }
        }
        #[inline(always)]
        fn nge(self, o: Self) -> __m128 {
            unsafe { _mm_cmpnge_ps(self.0, o.0) }
        }
        #[inline(always)]
        fn gt(self, o: Self) -> __m128 {
            unsafe { _mm_cmpgt_ps(self.0, o.0) }
        }
        #[inline(always)]
        fn lt(self, o: Self) -> __m128 {
            unsafe { _mm_cmplt_ps(self.0, o.0) }
        }

        #[inline(always)]
        fn and(a: __m128, b: __m128) -> __m128 {
            unsafe { _mm_and_ps(a, b) }
        }
        #[inline(always)]
        fn bits(m: __m128) -> u32 {
            unsafe { _mm_movemask_ps(m) as u32 }
        }
    }
}

/// Eight f32 lanes in AVX registers, for the filter of two blocks at once (x86-64 with the `avx`
/// feature; the processor is asked at run time, [`avx::available`]).
///
/// Every method is an always-inline wrapper of an AVX intrinsic, which executes only on a processor
/// with AVX and inlines only into code compiled with it: so the type is used only in code reached
/// from `PreparedRay::dispatch_avx` (compiled with AVX, called after [`avx::available`]) and from
/// tests that asked the same (where a wrapper is not inlined, it calls the intrinsic: slower,
/// still only after the check). The operations are the same IEEE operations lane by lane as
/// [`F4`]'s (no fused multiply-add: the walks are compiled for AVX, not FMA), so eight lanes give
/// the bits two calls of four give.
#[cfg(all(target_arch = "x86_64", feature = "avx"))]
pub(crate) mod avx {
    // The intrinsics need AVX, which the caller's context provides, not these wrappers': each call
    // is `unsafe` under that one invariant (the type's docs).
    #![allow(clippy::undocumented_unsafe_blocks)]

    use core::arch::x86_64::*;
    #[cfg(not(miri))]
    use core::sync::atomic::{AtomicU8, Ordering};

    use super::Lanes;

    /// Whether this processor and its operating system run AVX instructions (CPUID's AVX and
    /// OSXSAVE bits, and XCR0 enabling the SSE and AVX state), asked once and remembered. False
    /// under Miri, which does not emulate CPUID.
    #[inline(always)]
    pub(crate) fn available() -> bool {
        #[cfg(miri)]
        {
            false
        }
        #[cfg(not(miri))]
        {
            // 0 = not asked yet, 1 = no, 2 = yes. Relaxed: every thread computes the same answer.
            static STATE: AtomicU8 = AtomicU8::new(0);
            match STATE.load(Ordering::Relaxed) {
                2 => true,
                1 => false,
                _ => {
                    let yes = detect();
                    STATE.store(if yes { 2 } else { 1 }, Ordering::Relaxed);
                    yes
                }
            }
        }
    }

    #[cfg(not(miri))]
    #[cold]
    fn detect() -> bool {
        // SAFETY: CPUID exists on every x86-64 processor (`unsafe` in older compilers only).
        #[allow(unused_unsafe)]
        let leaf1 = unsafe { __cpuid(1) };
        let (osxsave, avx) = (leaf1.ecx & (1 << 27) != 0, leaf1.ecx & (1 << 28) != 0);
        if !(osxsave && avx) {
            return false;
        }
        // SAFETY: OSXSAVE set means the OS enabled XGETBV.
        let xcr0 = unsafe { xcr0() };
        xcr0 & 0b110 == 0b110
    }

    #[cfg(not(miri))]
    #[target_feature(enable = "xsave")]
    unsafe fn xcr0() -> u64 {
        _xgetbv(0)
    }

    /// Eight lanes (see the module docs for where a value may exist).
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Avx(__m256);

    impl Avx {
        /// The eight lanes' values (tests; AVX code only, as every use of the type).
        #[cfg(test)]
        #[inline(always)]
        pub(crate) fn to_array(self) -> [f32; 8] {
            let mut out = [0.0; 8];
            unsafe { _mm256_storeu_ps(out.as_mut_ptr(), self.0) };
            out
        }

        /// Lanes 0..4 from `a`, 4..8 from `b`.
        #[inline(always)]
        pub(crate) fn load_pair(a: &[f32; 4], b: &[f32; 4]) -> Self {
            // `a`, `b` are 16 readable bytes each; the unaligned loads need no alignment.
            Avx(unsafe { _mm256_loadu2_m128(b.as_ptr(), a.as_ptr()) })
        }
    }

    impl Lanes for Avx {
        const WIDTH: u32 = 8;
        type Mask = __m256;
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Avx(unsafe { _mm256_set1_ps(x) })
        }
        /// The same four lanes twice.
        #[inline(always)]
        fn load(v: &[f32; 4]) -> Self {
            Self::load_pair(v, v)
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Avx(unsafe { _mm256_add_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Avx(unsafe { _mm256_sub_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Avx(unsafe { _mm256_mul_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Avx(unsafe { _mm256_div_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            Avx(unsafe { _mm256_max_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            Avx(unsafe { _mm256_min_ps(self.0, o.0) })
        }
        #[inline(always)]
        fn abs(self) -> Self {
            let mask = unsafe { _mm256_castsi256_ps(_mm256_set1_epi32(0x7fff_ffff)) };
            Avx(unsafe { _mm256_and_ps(self.0, mask) })
        }
        #[inline(always)]
        fn neg(self) -> Self {
            Avx(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
        }
        #[inline(always)]
        fn nle(self, o: Self) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_NLE_UQ>(self.0, o.0) }
        }
        #[inline(always)]
        fn nge(self, o: Self) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_NGE_UQ>(self.0, o.0) }
        }
        #[inline(always)]
        fn gt(self, o: Self) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_GT_OQ>(self.0, o.0) }
        }
        #[inline(always)]
        fn lt(self, o: Self) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(self.0, o.0) }
        }
        #[inline(always)]
        fn and(a: __m256, b: __m256) -> __m256 {
            unsafe { _mm256_and_ps(a, b) }
        }
        #[inline(always)]
        fn bits(m: __m256) -> u32 {
            unsafe { _mm256_movemask_ps(m) as u32 }
        }
        /// Every sign bit set: `vtestps` against all ones (carry set when `!m & ones` has none).
        #[inline(always)]
        fn all(m: __m256) -> bool {
            unsafe {
                let ones = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
                _mm256_testc_ps(m, ones) != 0
            }
        }
    }
}

#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
mod neon {
    // As for SSE2: safe under the target feature in newer compilers, `unsafe` in older ones.
    #![allow(unused_unsafe)]

    use core::arch::aarch64::*;

    use super::Lanes;

    /// Four lanes in a NEON register.
    #[derive(Clone, Copy, Debug)]
    pub(crate) struct Neon(float32x4_t);

    impl Lanes for Neon {
        const WIDTH: u32 = 4;
        type Mask = uint32x4_t;
        #[inline(always)]
        fn splat(x: f32) -> Self {
            Neon(unsafe { vdupq_n_f32(x) })
        }
        #[inline(always)]
        fn load(v: &[f32; 4]) -> Self {
            // SAFETY: `v` is four readable f32.
            Neon(unsafe { vld1q_f32(v.as_ptr()) })
        }
        #[inline(always)]
        fn add(self, o: Self) -> Self {
            Neon(unsafe { vaddq_f32(self.0, o.0) })
        }
        #[inline(always)]
        fn sub(self, o: Self) -> Self {
            Neon(unsafe { vsubq_f32(self.0, o.0) })
        }
        #[inline(always)]
        fn mul(self, o: Self) -> Self {
            Neon(unsafe { vmulq_f32(self.0, o.0) })
        }
        #[inline(always)]
        fn div(self, o: Self) -> Self {
            Neon(unsafe { vdivq_f32(self.0, o.0) })
        }
        #[inline(always)]
        fn max(self, o: Self) -> Self {
            Neon(unsafe { vmaxq_f32(self.0, o.0) })
        }
        #[inline(always)]
        fn min(self, o: Self) -> Self {
            Neon(unsafe { vminq_f32(self.0, o.0) })
        }
        #[inline(always)]
        fn abs(self) -> Self {
            Neon(unsafe { vabsq_f32(self.0) })
        }
        #[inline(always)]
        fn neg(self) -> Self {
            Neon(unsafe { vnegq_f32(self.0) })
        }
        #[inline(always)]
        fn nle(self, o: Self) -> uint32x4_t {
            unsafe { vmvnq_u32(vcleq_f32(self.0, o.0)) }
        }
        #[inline(always)]
        fn nge(self, o: Self) -> uint32x4_t {
            unsafe { vmvnq_u32(vcgeq_f32(self.0, o.0)) }
        }
        #[inline(always)]
        fn gt(self, o: Self) -> uint32x4_t {
            unsafe { vcgtq_f32(self.0, o.0) }
        }
        #[inline(always)]
        fn lt(self, o: Self) -> uint32x4_t {
            unsafe { vcltq_f32(self.0, o.0) }
        }

        #[inline(always)]
        fn and(a: uint32x4_t, b: uint32x4_t) -> uint32x4_t {
            unsafe { vandq_u32(a, b) }
        }
        #[inline(always)]
        fn bits(m: uint32x4_t) -> u32 {
            let weights = [1u32, 2, 4, 8];
            // SAFETY: `weights` is four readable u32.
            unsafe { vaddvq_u32(vandq_u32(m, vld1q_u32(weights.as_ptr()))) }
        }
    }
}

/// The lanes the filter runs on for this target.
#[cfg(all(
    any(target_arch = "x86", target_arch = "x86_64"),
    target_feature = "sse2"
))]
pub(crate) type F4 = sse2::Sse2;
/// The lanes the filter runs on for this target.
#[cfg(all(target_arch = "aarch64", target_feature = "neon"))]
pub(crate) type F4 = neon::Neon;
/// The lanes the filter runs on for this target.
#[cfg(not(any(
    all(
        any(target_arch = "x86", target_arch = "x86_64"),
        target_feature = "sse2"
    ),
    all(target_arch = "aarch64", target_feature = "neon")
)))]
pub(crate) type F4 = Portable;
