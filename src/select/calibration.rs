//! The machine's cost constants and their binary blob (format in README.md, "Calibration blob").

use crate::error::CalibError;

/// One constant of the calibration: its name, its documented range, and what it means.
#[derive(Clone, Copy, Debug)]
pub struct Constant {
    /// Name used in messages and in the README's table.
    pub name: &'static str,
    /// Smallest accepted value.
    pub min: f64,
    /// Largest accepted value.
    pub max: f64,
    /// What it measures.
    pub meaning: &'static str,
}

/// The constants in blob order. Appending is a minor format change; anything else is a major one.
pub const CONSTANTS: [Constant; 9] = [
    Constant {
        name: "grid_build_ns_per_triangle",
        min: 0.0,
        max: 1e6,
        meaning: "grid build time per triangle (reported, not needed to decide)",
    },
    Constant {
        name: "grid_ns_per_ray",
        min: 0.0,
        max: 1e6,
        meaning: "fixed grid cost per ray",
    },
    Constant {
        name: "grid_ns_per_cell",
        min: 0.0,
        max: 1e6,
        meaning: "grid traversal time per cell visited",
    },
    Constant {
        name: "grid_ns_per_test",
        min: 0.0,
        max: 1e6,
        meaning: "grid time per triangle test",
    },
    Constant {
        name: "kd_build_ns_per_nlogn",
        min: 0.0,
        max: 1e6,
        meaning: "kd-tree build time per N·log2 N",
    },
    Constant {
        name: "kd_build_ns_per_nlogn_per_grid_ref",
        min: 0.0,
        max: 1e6,
        meaning: "kd-tree build time per N·log2 N per grid reference per triangle",
    },
    Constant {
        name: "kd_ns_per_ray",
        min: 0.0,
        max: 1e6,
        meaning: "fixed kd-tree cost per ray",
    },
    Constant {
        name: "kd_ns_per_grid_cell",
        min: 0.0,
        max: 1e6,
        meaning: "kd-tree time per cell the same ray visits on the grid",
    },
    Constant {
        name: "kd_ns_per_grid_test",
        min: 0.0,
        max: 1e6,
        meaning: "kd-tree time per triangle test the same ray makes on the grid",
    },
];

/// Number of constants in this layout.
pub const CONSTANT_COUNT: usize = CONSTANTS.len();

/// Machine constants for the cost model.
///
/// Guarantees: every value is finite and inside its [`CONSTANTS`] range (the only ways to make one are
/// [`Calibration::new`] and [`Calibration::from_bytes`], which check).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    machine: u64,
    build: u64,
    values: [f64; CONSTANT_COUNT],
}

/// Blob magic: the first eight bytes of every calibration blob.
pub const MAGIC: [u8; 8] = *b"RQCALIB\0";
/// Major format version this reader understands (3: the kd-tree's per-ray cost priced on the
/// grid's counts, and its build on the grid's references, in place of format 2's hit fraction).
pub const FORMAT_MAJOR: u16 = 3;
/// Minor format version this writer produces.
pub const FORMAT_MINOR: u16 = 0;
/// Bytes before the payload.
pub const HEADER_LEN: usize = 32;
/// Bytes of the trailing CRC-32.
pub const CRC_LEN: usize = 4;
/// Size of the blob this version writes.
pub const BLOB_LEN: usize = HEADER_LEN + 4 + 8 * CONSTANT_COUNT + CRC_LEN;

/// Fingerprint of the code that wrote a blob: FNV-1a of the crate version, mixed with the target
/// architecture's.
pub const BUILD_FINGERPRINT: u64 =
    fnv1a(env!("CARGO_PKG_VERSION").as_bytes()) ^ fnv1a(TARGET_ARCH.as_bytes()).rotate_left(17);

#[cfg(target_arch = "x86_64")]
const TARGET_ARCH: &str = "x86_64";
#[cfg(target_arch = "aarch64")]
const TARGET_ARCH: &str = "aarch64";
#[cfg(not(any(target_arch = "x86_64", target_arch = "aarch64")))]
const TARGET_ARCH: &str = "other";

/// The model variant (`select::validate::VARIANTS`) [`BUILTIN`] was fitted with.
pub const BUILTIN_VARIANT: &str = "kd build without grid references";

/// The calibration compiled into the library: fitted by `cargo run --release --example calibrate
/// -- --variant "kd build without grid references" --repeats 9` (its defaults: the bundled scenes
/// plus the procedural set, 23 scenes) on the project's 2-core x86-64 VM, an AMD EPYC with AVX, at
/// stop 34, after the AVX filter (stop 33) and the fuller grid cells and kd-tree leaves of stop 34
/// (λ = 0.35, `C_i` = 0.35): the grid's fixed cost per ray 68.0 ns, a cell 22.8, a test 1.25; the
/// kd-tree's build 26.2 ns per N·log2 N, its ray 99.8 ns plus 4.24 per grid cell and 2.03 per grid
/// test. Until stop 34 the values were stop 27's, fitted on an Intel Xeon VM (the grid 70.3, 13.8
/// and 1.04; the kd-tree 24.8, 90.1, 2.59 and 1.63), kept through stops 28–33 because refits
/// (stop 28 on the Intel VM, stop 31 on this one) changed no decision for the better within one
/// run's noise. This one does: a cell now costs 18.3 tests instead of 13.2, and the check after a
/// kd-tree build (`decision::kd_tree_confirmed`, whose verdict depends on the calibration through
/// that ratio) keeps stadium-1M's kd-tree, which it used to drop although it is 1.5–1.9× faster
/// per ray here
/// (the grid's 207 MB miss the cache, which its counted work does not show). Evaluation runs
/// (docs/performance.md, "Stop 34"): the check kept the faster structure on 24–29 of 31 scenes
/// with a loss of 0.17–0.54 in five runs with these values, against 26 and 1.20 in one with the
/// old; the worst regret 1.39–1.78 (the estimates' errors on tetra-10k and stadium-1M) against
/// 1.90 (the check dropping stadium-1M's kd-tree); the interior camera at 4 occlusion rays a hit
/// 1.010–1.147 against 1.059 (this case's spread between runs is larger than the change). Since
/// stop 27 a switch the tapped rays ask for waits for a second batch to ask too (issue 14's
/// interior case: the tapped primary rays overstate the kd-tree's saving on the occlusion rays
/// after them).
/// `calib/default.rqcal` holds the same values as a blob (a test keeps the
/// two identical), with the kd-tree binned at every node, 4 to 32 bins (`KdTreeParams::DEFAULT`
/// since stop 20). A refit at stop 42 on the Intel Xeon VM (the grid 54.8, 13.2 and 0.89; the
/// kd-tree 18.4, 71.4, 2.87 and 1.35) was not adopted: with the same counts and times (`raycost
/// check 1` with each calibration against `raycost time 5`, 31 scenes) its check after a kd-tree
/// build differs from the built-in values' on two scenes, rightly on gears-10k (the built-in values
/// keep a kd-tree 5 % slower) and wrongly on stadium-1M (it drops one 12 % faster), where the
/// built-in values' verdict is a near-tie, both structures priced 121.28 ns a ray
/// (docs/performance.md, "Stop 42"). The kd-tree's build is one term per N·log2 N (the median over the
/// scenes): at stop 24, fitted with a second term per grid reference
/// per triangle as well (5.1 + 6.4 per reference), least squares pulled towards the cheap Sierpinski
/// tetrahedra and the dear slivers and predicted 0.58–0.76× the build on 19 of 29 of the
/// evaluation's scenes (median error 32 %, against the builds measured by the evaluation that
/// docs/evaluation.md then held, out of sample for most), where the one term was off by a median
/// 14 % (0.12 on slivers-2k and 0.61 on hair-50k, whose kd-trees are slower per ray than the grid
/// anyway, and 2.4–2.5 on the tetrahedra; all stop 24's figures). Until stop 23 the build was
/// 16.0 ns per N·log2 N per grid reference per triangle. The kd-tree per ray is a constant plus
/// terms per grid cell and per grid test; it follows the rays (a camera inside a building makes both
/// structures' estimates grow). The grid and the kd-tree are within a few percent per ray on many
/// of these scenes, so W*'s leave-one-out error is dominated by scenes whose W* is infinite on one
/// side (docs/evaluation.md), and the variant is chosen by the build's error rather than by that
/// median, which moves by ±10 % between runs on the same machine. Prices for both cells and tests
/// are kept, which the check after a kd-tree build (`decision::kd_tree_confirmed`) needs.
pub const BUILTIN: Calibration = Calibration {
    machine: 0,
    build: 0,
    values: [
        27.992019653317723,
        67.95634878085036,
        22.818374833621835,
        1.2459770158898835,
        26.21680439000975,
        0.0,
        99.80313906669828,
        4.238767131213792,
        2.033401397440324,
    ],
};

impl Calibration {
    /// A calibration from values in [`CONSTANTS`] order, refused when any is out of range.
    pub fn new(machine: u64, values: [f64; CONSTANT_COUNT]) -> Result<Calibration, CalibError> {
        check_values(&values)?;
        Ok(Calibration {
            machine,
            build: BUILD_FINGERPRINT,
            values,
        })
    }

    /// The built-in calibration.
    pub const fn builtin() -> &'static Calibration {
        &BUILTIN
    }

    /// The value of constant `i` in [`CONSTANTS`] order.
    pub fn value(&self, i: usize) -> f64 {
        self.values.get(i).copied().unwrap_or(0.0)
    }

    /// All values in [`CONSTANTS`] order.
    pub fn values(&self) -> &[f64; CONSTANT_COUNT] {
        &self.values
    }

    /// Fingerprint of the machine that produced it (0 = not tied to a machine).
    pub fn machine_fingerprint(&self) -> u64 {
        self.machine
    }

    /// Fingerprint of the build that produced it.
    pub fn build_fingerprint(&self) -> u64 {
        self.build
    }

    /// Writes the blob into `buf`, returning its length ([`BLOB_LEN`]).
    pub fn to_bytes(&self, buf: &mut [u8]) -> Result<usize, CalibError> {
        let out = buf
            .get_mut(..BLOB_LEN)
            .ok_or(CalibError::BufferTooSmall { needed: BLOB_LEN })?;
        out[0..8].copy_from_slice(&MAGIC);
        out[8..10].copy_from_slice(&FORMAT_MAJOR.to_le_bytes());
        out[10..12].copy_from_slice(&FORMAT_MINOR.to_le_bytes());
        let payload_len = (BLOB_LEN - HEADER_LEN - CRC_LEN) as u32;
        out[12..16].copy_from_slice(&payload_len.to_le_bytes());
        out[16..24].copy_from_slice(&self.machine.to_le_bytes());
        out[24..32].copy_from_slice(&self.build.to_le_bytes());
        out[32..36].copy_from_slice(&(CONSTANT_COUNT as u32).to_le_bytes());
        for (i, v) in self.values.iter().enumerate() {
            let at = 36 + 8 * i;
            out[at..at + 8].copy_from_slice(&v.to_le_bytes());
        }
        let crc = crc32(&out[..BLOB_LEN - CRC_LEN]);
        out[BLOB_LEN - CRC_LEN..].copy_from_slice(&crc.to_le_bytes());
        Ok(BLOB_LEN)
    }

    /// Reads a blob, checking magic, version, length, CRC and every value before a calibration
    /// exists. Constants appended by a newer minor version are ignored.
    pub fn from_bytes(data: &[u8]) -> Result<Calibration, CalibError> {
        let truncated = |expected: usize| CalibError::Truncated {
            expected,
            got: data.len(),
        };
        let magic = data.get(0..8).ok_or(truncated(HEADER_LEN + CRC_LEN))?;
        if magic != MAGIC {
            return Err(CalibError::BadMagic);
        }
        let header = data
            .get(..HEADER_LEN)
            .ok_or(truncated(HEADER_LEN + CRC_LEN))?;
        let major = u16::from_le_bytes([header[8], header[9]]);
        if major != FORMAT_MAJOR {
            return Err(CalibError::UnsupportedVersion { major });
        }
        let payload_len =
            u32::from_le_bytes([header[12], header[13], header[14], header[15]]) as usize;
        let total = HEADER_LEN
            .checked_add(payload_len)
            .and_then(|n| n.checked_add(CRC_LEN))
            .ok_or(truncated(usize::MAX))?;
        if data.len() != total {
            return Err(truncated(total));
        }
        let (body, crc_bytes) = data.split_at(total - CRC_LEN);
        let crc = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
        if crc32(body) != crc {
            return Err(CalibError::Checksum);
        }
        let payload = &body[HEADER_LEN..];
        let count = payload
            .get(0..4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize);
        // The payload holds its count of constants (at least this layout's), then perhaps fields
        // of a newer minor layout: the constants this reader knows are read, the rest ignored.
        let known = 4 + 8 * CONSTANT_COUNT;
        match count {
            Some(c) if c >= CONSTANT_COUNT && (payload.len() - 4) / 8 >= c => {}
            _ => return Err(truncated(HEADER_LEN + known + CRC_LEN)),
        }
        let mut values = [0.0; CONSTANT_COUNT];
        for (i, v) in values.iter_mut().enumerate() {
            let at = 4 + 8 * i;
            let mut b = [0u8; 8];
            b.copy_from_slice(&payload[at..at + 8]);
            *v = f64::from_le_bytes(b);
        }
        check_values(&values)?;
        let machine = u64::from_le_bytes(
            header[16..24]
                .try_into()
                .map_err(|_| truncated(HEADER_LEN))?,
        );
        let build = u64::from_le_bytes(
            header[24..32]
                .try_into()
                .map_err(|_| truncated(HEADER_LEN))?,
        );
        Ok(Calibration {
            machine,
            build,
            values,
        })
    }
}

impl Default for Calibration {
    fn default() -> Self {
        BUILTIN
    }
}

fn check_values(values: &[f64; CONSTANT_COUNT]) -> Result<(), CalibError> {
    for (v, c) in values.iter().zip(CONSTANTS.iter()) {
        if !(v.is_finite() && *v >= c.min && *v <= c.max) {
            return Err(CalibError::ValueOutOfRange { field: c.name });
        }
    }
    Ok(())
}

/// CRC-32 (IEEE 802.3, reflected, polynomial 0xEDB88320), the checksum of zlib and PNG.
pub fn crc32(data: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in data {
        crc = CRC_TABLE[((crc ^ u32::from(b)) & 0xFF) as usize] ^ (crc >> 8);
    }
    !crc
}

const CRC_TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 {
                0xEDB8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

const fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    let mut i = 0;
    while i < bytes.len() {
        h ^= bytes[i] as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
        i += 1;
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32_matches_the_standard_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn round_trip() {
        let mut buf = [0u8; BLOB_LEN];
        let c = Calibration::new(42, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]).unwrap();
        assert_eq!(c.to_bytes(&mut buf), Ok(BLOB_LEN));
        assert_eq!(Calibration::from_bytes(&buf), Ok(c));
    }

    #[test]
    fn every_truncation_and_every_flip_is_refused() {
        let mut buf = [0u8; BLOB_LEN];
        BUILTIN.to_bytes(&mut buf).unwrap();
        for len in 0..BLOB_LEN {
            assert!(
                Calibration::from_bytes(&buf[..len]).is_err(),
                "length {len} accepted"
            );
        }
        for i in 0..BLOB_LEN {
            for bit in 0..8 {
                let mut b = buf;
                b[i] ^= 1 << bit;
                assert!(
                    Calibration::from_bytes(&b).is_err(),
                    "flip of bit {bit} in byte {i} accepted"
                );
            }
        }
    }

    #[test]
    fn out_of_range_values_are_refused_even_with_a_good_crc() {
        for bad in [f64::NAN, f64::INFINITY, -1.0, 1e300] {
            let mut c = BUILTIN;
            c.values[3] = bad;
            let mut buf = [0u8; BLOB_LEN];
            c.to_bytes(&mut buf).unwrap();
            assert_eq!(
                Calibration::from_bytes(&buf),
                Err(CalibError::ValueOutOfRange {
                    field: CONSTANTS[3].name
                })
            );
        }
    }

    #[test]
    fn newer_minor_layout_with_appended_constants_is_read() {
        let mut buf = [0u8; BLOB_LEN + 8];
        BUILTIN.to_bytes(&mut buf).unwrap();
        // Rewrite as a newer minor with one more constant.
        buf[10..12].copy_from_slice(&(FORMAT_MINOR + 1).to_le_bytes());
        let payload_len = (BLOB_LEN + 8 - HEADER_LEN - CRC_LEN) as u32;
        buf[12..16].copy_from_slice(&payload_len.to_le_bytes());
        buf[32..36].copy_from_slice(&((CONSTANT_COUNT + 1) as u32).to_le_bytes());
        let end = BLOB_LEN + 8 - CRC_LEN;
        buf[end - 8..end].copy_from_slice(&123.0f64.to_le_bytes());
        let crc = crc32(&buf[..end]);
        buf[end..].copy_from_slice(&crc.to_le_bytes());
        assert_eq!(
            Calibration::from_bytes(&buf).map(|c| c.values),
            Ok(BUILTIN.values)
        );
    }
}
