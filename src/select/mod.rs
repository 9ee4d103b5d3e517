//! Choosing the structure: the calibration (machine constants), the cost model, the sample rays
//! that feed it, the decision rule, and the fit that makes a calibration from measurements.

pub mod calibration;
pub mod clock;
pub mod decision;
pub mod fit;
#[cfg(feature = "std")]
pub mod measure;
pub mod model;
pub mod sample;
pub mod validate;
