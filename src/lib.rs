//! rayq: a ray query core for triangle meshes.
//!
//! It builds a uniform grid in linear time and a SAH kd-tree, picks the one that finishes a ray budget
//! first ([`Scene`]), answers closest-hit and any-hit queries with one exact triangle test shared by
//! every structure ([`triangle`]), and is exported to C through `include/rayq.h` (feature `capi`). The core is `no_std` + `alloc`: every allocation during a build is
//! fallible and counted against an optional memory limit, and queries never allocate.
//!
//! Start with [`Scene::build`], or with [`UniformGrid::build`] when you want one structure directly.
#![no_std]
#![warn(missing_docs)]
// `!(a <= b)` is how this crate says "false when either side is NaN"; it is deliberate.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

#[cfg(not(any(feature = "std", feature = "libm")))]
compile_error!("rayq needs float math: enable feature `std` (default) or feature `libm`");

#[cfg(all(feature = "bare-rt", feature = "std"))]
compile_error!(
    "feature `bare-rt` brings its own panic handler and allocator: build it with --no-default-features"
);

extern crate alloc;
#[cfg(feature = "std")]
extern crate std;

pub mod accel;
pub mod bigvec;
pub mod budget;
pub mod error;
pub mod geometry;
mod math;
pub mod mesh;
pub mod procedural;
pub mod ray;
pub mod scene;
pub mod select;
pub mod triangle;
pub mod workload;

#[cfg(feature = "capi")]
pub mod capi;
#[cfg(feature = "obj")]
pub mod obj;

pub use accel::brute::BruteForce;
pub use accel::grid::{GridParams, UniformGrid};
pub use accel::kdtree::{KdTree, KdTreeParams};
pub use accel::RayQuery;
pub use budget::MemoryBudget;
pub use error::{BuildError, CalibError, MeshError};
pub use mesh::TriMesh;
pub use ray::{Aabb, Hit, Ray};
pub use scene::{BudgetKind, BuildOptions, Scene, Structure, RAYS_REMAINING_NONE};
pub use select::calibration::Calibration;
pub use triangle::packs::TriangleLayout;

/// The README's Rust example is compiled and run as a doctest.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
