//! Errors of mesh validation, builds and calibration blobs. Each failure has its own variant so that
//! the C boundary can give it its own status and message.

use core::fmt;

/// Why a mesh was refused. Nothing is built from a refused mesh.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshError {
    /// The vertex stride is below 12 bytes (three `f32`).
    StrideTooSmall {
        /// The stride given, in bytes.
        stride: usize,
    },
    /// A vertex coordinate is NaN or infinite.
    NonFiniteVertex {
        /// Index of the vertex.
        vertex: usize,
    },
    /// A triangle names a vertex that does not exist.
    IndexOutOfRange {
        /// Index of the triangle.
        triangle: usize,
        /// The offending vertex index.
        index: u32,
        /// How many vertices the mesh has.
        vertex_count: usize,
    },
    /// A count whose byte size overflows `usize`, or a triangle count that does not fit the 32-bit
    /// primitive ids (`RQ_INVALID_ID` is reserved).
    CountOverflow {
        /// Which count.
        what: &'static str,
    },
    /// Vertex or index data is missing while its count is not zero.
    MissingData {
        /// Which array.
        what: &'static str,
    },
}

/// Why a build failed. A failed build leaves nothing allocated behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BuildError {
    /// The mesh was refused.
    InvalidMesh(MeshError),
    /// One geometry of a scene of several was refused.
    InvalidGeometry {
        /// Which geometry (its index in the caller's list).
        geometry: usize,
        /// Why.
        error: MeshError,
    },
    /// The allocator refused memory.
    OutOfMemory {
        /// What was being allocated.
        what: &'static str,
        /// Bytes requested.
        bytes: usize,
    },
    /// The allocation would have taken the build past its memory limit.
    MemoryLimit {
        /// What was being allocated.
        what: &'static str,
        /// Bytes the build would have held.
        needed: usize,
        /// The limit in bytes.
        limit: usize,
    },
    /// A size that the structure's 32-bit offsets cannot address.
    CapacityExceeded {
        /// What overflowed.
        what: &'static str,
    },
    /// The requested structure or mode is not available in this build.
    Unsupported {
        /// What is missing.
        what: &'static str,
    },
    /// An option is out of range.
    InvalidArgument {
        /// Which option.
        what: &'static str,
    },
    /// The caller's memory monitor refused an allocation.
    Cancelled {
        /// What was being allocated.
        what: &'static str,
        /// Bytes the build would have held.
        held: usize,
    },
}

impl From<MeshError> for BuildError {
    fn from(e: MeshError) -> Self {
        BuildError::InvalidMesh(e)
    }
}

/// Why a calibration blob was refused. No calibration exists until every check passed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CalibError {
    /// The first bytes are not the rayq calibration magic.
    BadMagic,
    /// A major format version this reader does not know.
    UnsupportedVersion {
        /// Major version found.
        major: u16,
    },
    /// Fewer (or more) bytes than the header declares.
    Truncated {
        /// Bytes the header declares (or the minimum header size).
        expected: usize,
        /// Bytes given.
        got: usize,
    },
    /// The CRC-32 does not match the bytes.
    Checksum,
    /// A constant is NaN, infinite or outside its documented range.
    ValueOutOfRange {
        /// Name of the constant.
        field: &'static str,
    },
    /// The output buffer is too small for the blob.
    BufferTooSmall {
        /// Bytes the blob needs.
        needed: usize,
    },
}

impl fmt::Display for MeshError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            MeshError::StrideTooSmall { stride } => {
                write!(f, "vertex stride {stride} is below 12 bytes (three floats)")
            }
            MeshError::NonFiniteVertex { vertex } => {
                write!(f, "vertex {vertex} has a NaN or infinite coordinate")
            }
            MeshError::IndexOutOfRange {
                triangle,
                index,
                vertex_count,
            } => write!(
                f,
                "triangle {triangle} names vertex {index} but the mesh has {vertex_count} vertices"
            ),
            MeshError::CountOverflow { what } => write!(f, "{what} is too large"),
            MeshError::MissingData { what } => {
                write!(f, "{what} is NULL but its count is not zero")
            }
        }
    }
}

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            BuildError::InvalidMesh(e) => write!(f, "invalid mesh: {e}"),
            BuildError::InvalidGeometry { geometry, error } => {
                write!(f, "invalid geometry {geometry}: {error}")
            }
            BuildError::OutOfMemory { what, bytes } => {
                write!(f, "out of memory allocating {bytes} bytes for {what}")
            }
            BuildError::MemoryLimit { what, needed, limit } => write!(
                f,
                "memory limit of {limit} bytes reached: {what} would bring the build to {needed} bytes"
            ),
            BuildError::CapacityExceeded { what } => write!(f, "{what} exceeds 32-bit offsets"),
            BuildError::Unsupported { what } => write!(f, "{what} is not supported by this build"),
            BuildError::InvalidArgument { what } => write!(f, "invalid argument: {what}"),
            BuildError::Cancelled { what, held } => write!(
                f,
                "cancelled by the memory monitor: {what} would bring the build to {held} bytes"
            ),
        }
    }
}

impl fmt::Display for CalibError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            CalibError::BadMagic => write!(f, "not a rayq calibration blob (bad magic)"),
            CalibError::UnsupportedVersion { major } => {
                write!(
                    f,
                    "calibration format major version {major} is not supported"
                )
            }
            CalibError::Truncated { expected, got } => {
                write!(
                    f,
                    "calibration blob has {got} bytes, its header declares {expected}"
                )
            }
            CalibError::Checksum => write!(f, "calibration blob CRC-32 mismatch"),
            CalibError::ValueOutOfRange { field } => {
                write!(
                    f,
                    "calibration constant {field} is not finite or out of range"
                )
            }
            CalibError::BufferTooSmall { needed } => {
                write!(
                    f,
                    "buffer too small: the calibration blob needs {needed} bytes"
                )
            }
        }
    }
}
