//! The one place float functions come from: std when it is there, libm otherwise.

#[cfg(feature = "std")]
mod imp {
    // Only the triangle test's generator of test cases needs it.
    #[cfg(test)]
    #[inline(always)]
    pub fn floor(x: f32) -> f32 {
        x.floor()
    }
    #[inline(always)]
    pub fn sqrt(x: f32) -> f32 {
        x.sqrt()
    }
    #[inline(always)]
    pub fn cbrt(x: f64) -> f64 {
        x.cbrt()
    }
    #[inline(always)]
    pub fn sqrt64(x: f64) -> f64 {
        x.sqrt()
    }
    #[inline(always)]
    pub fn floor64(x: f64) -> f64 {
        x.floor()
    }
    #[inline(always)]
    pub fn log2_64(x: f64) -> f64 {
        x.log2()
    }
    #[inline(always)]
    pub fn sin(x: f32) -> f32 {
        x.sin()
    }
    #[inline(always)]
    pub fn cos(x: f32) -> f32 {
        x.cos()
    }
}

#[cfg(not(feature = "std"))]
mod imp {
    #[cfg(test)]
    #[inline(always)]
    pub fn floor(x: f32) -> f32 {
        libm::floorf(x)
    }
    #[inline(always)]
    pub fn sqrt(x: f32) -> f32 {
        libm::sqrtf(x)
    }
    #[inline(always)]
    pub fn cbrt(x: f64) -> f64 {
        libm::cbrt(x)
    }
    #[inline(always)]
    pub fn sqrt64(x: f64) -> f64 {
        libm::sqrt(x)
    }
    #[inline(always)]
    pub fn floor64(x: f64) -> f64 {
        libm::floor(x)
    }
    #[inline(always)]
    pub fn log2_64(x: f64) -> f64 {
        libm::log2(x)
    }
    #[inline(always)]
    pub fn sin(x: f32) -> f32 {
        libm::sinf(x)
    }
    #[inline(always)]
    pub fn cos(x: f32) -> f32 {
        libm::cosf(x)
    }
}

#[allow(unused_imports)]
pub use imp::*;
