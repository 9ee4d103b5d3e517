//! Choosing the structure: the calibration (machine constants) and, later, the cost model and the
//! decision rule.

pub mod calibration;
pub mod decision;
