//! What the reader ([`super`]) and the writer ([`super::write`]) must agree on byte for byte:
//! the file magic, a grid's compression flags, the per-node metadata byte of OpenVDB's
//! node-value compression, and how each value type is stored. Each is defined once, here,
//! so that the two sides cannot drift apart: a file the writer makes is read back with the
//! same meaning for every byte.

/// OpenVDB's magic number (" BDV" followed by four zero bytes, little endian): the first
/// eight bytes of every file.
pub const MAGIC: u64 = 0x5644_4220;

/// A grid's compression flags (OpenVDB `io::COMPRESS_*`), stored as a `u32` in front of the
/// grid's metadata. They apply to every node of the grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub(crate) struct CompressionFlags(pub u32);

impl CompressionFlags {
    pub(crate) const NONE: Self = Self(0);
    /// zlib over each block of node values (`COMPRESS_ZIP`).
    pub(crate) const ZIP: Self = Self(0x1);
    /// Inactive node values left out where the node's metadata byte (see [`NodeMeta`])
    /// says how to restore them (`COMPRESS_ACTIVE_MASK`).
    pub(crate) const ACTIVE_MASK: Self = Self(0x2);
    /// blosc (LZ4) over each block of node values (`COMPRESS_BLOSC`).
    pub(crate) const BLOSC: Self = Self(0x4);

    /// Both sets of flags.
    pub(crate) const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }

    /// Every flag of `other` is set.
    pub(crate) fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// No bit outside the three flags OpenVDB defines is set.
    pub(crate) fn is_known(self) -> bool {
        self.0 & !(Self::ZIP.0 | Self::ACTIVE_MASK.0 | Self::BLOSC.0) == 0
    }

    /// Names of the set flags, for reports.
    pub(crate) fn names(self) -> Vec<&'static str> {
        [
            (Self::ZIP, "zip"),
            (Self::BLOSC, "blosc"),
            (Self::ACTIVE_MASK, "active_mask"),
        ]
        .into_iter()
        .filter(|&(flag, _)| self.contains(flag))
        .map(|(_, name)| name)
        .collect()
    }
}

/// The per-node metadata byte of OpenVDB's node-value compression (`io/Compression.h`):
/// which inactive values a node stores, and whether a selection mask follows to say which
/// of two inactive values each inactive entry holds. With [`CompressionFlags::ACTIVE_MASK`]
/// every code but [`NodeMeta::NoMaskAndAllVals`] then stores only the active values.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub(crate) enum NodeMeta {
    /// No inactive values, or all equal the background: only active values stored.
    NoMaskOrInactiveVals = 0,
    /// All inactive values are −background.
    NoMaskAndMinusBg = 1,
    /// All inactive values equal one other value, stored once.
    NoMaskAndOneInactiveVal = 2,
    /// A selection mask picks −background or +background per inactive value.
    MaskAndNoInactiveVals = 3,
    /// A selection mask picks the background or one stored value.
    MaskAndOneInactiveVal = 4,
    /// A selection mask picks one of two stored values.
    MaskAndTwoInactiveVals = 5,
    /// More than two distinct inactive values: every value is stored.
    NoMaskAndAllVals = 6,
}

impl NodeMeta {
    /// The code of a stored metadata byte, or `None` past 6.
    pub(crate) fn from_byte(byte: u8) -> Option<Self> {
        use NodeMeta::*;
        Some(match byte {
            0 => NoMaskOrInactiveVals,
            1 => NoMaskAndMinusBg,
            2 => NoMaskAndOneInactiveVal,
            3 => MaskAndNoInactiveVals,
            4 => MaskAndOneInactiveVal,
            5 => MaskAndTwoInactiveVals,
            6 => NoMaskAndAllVals,
            _ => return None,
        })
    }

    /// A selection mask (one bit per node entry) follows the inactive values.
    pub(crate) fn has_selection_mask(self) -> bool {
        matches!(
            self,
            NodeMeta::MaskAndNoInactiveVals
                | NodeMeta::MaskAndOneInactiveVal
                | NodeMeta::MaskAndTwoInactiveVals
        )
    }
}

/// Bit `n` of a node mask (child, value or selection mask: 64 entries per word, entry `n`
/// in bit `n % 64` of word `n / 64`).
pub(crate) fn mask_is_on(mask: &[u64], n: usize) -> bool {
    (mask[n >> 6] >> (n & 63)) & 1 == 1
}

/// A value type that a standard 5-4-3 tree stores: `float`, `double`, `vec3s`, `vec3d`, each
/// little endian, full precision or (read only) as 16-bit halves.
pub(crate) trait VdbValue:
    Copy + Default + PartialEq + std::fmt::Debug + Send + Sync + 'static
{
    /// The grid type name in the file (`Tree_float_5_4_3`, …).
    const TREE_TYPE: &'static str;
    /// The `value_type` metadata OpenVDB writes, and the name reports use.
    const VALUE_TYPE: &'static str;
    const IS_VECTOR: bool;
    /// Bytes per value at full precision.
    const SIZE: usize;
    /// Bytes per value when the grid is saved as half floats.
    const HALF_SIZE: usize;
    fn from_bytes(b: &[u8]) -> Self;
    fn from_half_bytes(b: &[u8]) -> Self;
    /// Appends the full-precision bytes.
    fn put(&self, out: &mut Vec<u8>);
    /// −value: OpenVDB's default for inactive values other than the background.
    fn negate(self) -> Self;
}

fn f32_at(b: &[u8], i: usize) -> f32 {
    f32::from_le_bytes([b[4 * i], b[4 * i + 1], b[4 * i + 2], b[4 * i + 3]])
}

fn f64_at(b: &[u8], i: usize) -> f64 {
    let mut a = [0u8; 8];
    a.copy_from_slice(&b[8 * i..8 * i + 8]);
    f64::from_le_bytes(a)
}

fn half_at(b: &[u8], i: usize) -> half::f16 {
    half::f16::from_le_bytes([b[2 * i], b[2 * i + 1]])
}

impl VdbValue for f32 {
    const TREE_TYPE: &'static str = "Tree_float_5_4_3";
    const VALUE_TYPE: &'static str = "float";
    const IS_VECTOR: bool = false;
    const SIZE: usize = 4;
    const HALF_SIZE: usize = 2;
    fn from_bytes(b: &[u8]) -> Self {
        f32_at(b, 0)
    }
    fn from_half_bytes(b: &[u8]) -> Self {
        half_at(b, 0).to_f32()
    }
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn negate(self) -> Self {
        -self
    }
}

impl VdbValue for f64 {
    const TREE_TYPE: &'static str = "Tree_double_5_4_3";
    const VALUE_TYPE: &'static str = "double";
    const IS_VECTOR: bool = false;
    const SIZE: usize = 8;
    const HALF_SIZE: usize = 2;
    fn from_bytes(b: &[u8]) -> Self {
        f64_at(b, 0)
    }
    fn from_half_bytes(b: &[u8]) -> Self {
        half_at(b, 0).to_f64()
    }
    fn put(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn negate(self) -> Self {
        -self
    }
}

impl VdbValue for [f32; 3] {
    const TREE_TYPE: &'static str = "Tree_vec3s_5_4_3";
    const VALUE_TYPE: &'static str = "vec3s";
    const IS_VECTOR: bool = true;
    const SIZE: usize = 12;
    const HALF_SIZE: usize = 6;
    fn from_bytes(b: &[u8]) -> Self {
        [f32_at(b, 0), f32_at(b, 1), f32_at(b, 2)]
    }
    fn from_half_bytes(b: &[u8]) -> Self {
        [0, 1, 2].map(|i| half_at(b, i).to_f32())
    }
    fn put(&self, out: &mut Vec<u8>) {
        for v in self {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    fn negate(self) -> Self {
        self.map(|v| -v)
    }
}

impl VdbValue for [f64; 3] {
    const TREE_TYPE: &'static str = "Tree_vec3d_5_4_3";
    const VALUE_TYPE: &'static str = "vec3d";
    const IS_VECTOR: bool = true;
    const SIZE: usize = 24;
    const HALF_SIZE: usize = 6;
    fn from_bytes(b: &[u8]) -> Self {
        [f64_at(b, 0), f64_at(b, 1), f64_at(b, 2)]
    }
    fn from_half_bytes(b: &[u8]) -> Self {
        [0, 1, 2].map(|i| half_at(b, i).to_f64())
    }
    fn put(&self, out: &mut Vec<u8>) {
        for v in self {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
    fn negate(self) -> Self {
        self.map(|v| -v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn node_meta_round_trips_its_byte() {
        for byte in 0..=6u8 {
            let meta = NodeMeta::from_byte(byte).expect("codes 0 to 6 exist");
            assert_eq!(meta as u8, byte);
            assert_eq!(meta.has_selection_mask(), (3..=5).contains(&byte));
        }
        assert_eq!(NodeMeta::from_byte(7), None);
    }

    #[test]
    fn flags_are_openvdb_bits() {
        let zip = CompressionFlags::ZIP.union(CompressionFlags::ACTIVE_MASK);
        assert_eq!(zip.0, 0x3);
        assert_eq!(zip.names(), ["zip", "active_mask"]);
        assert_eq!(CompressionFlags::BLOSC.names(), ["blosc"]);
        assert!(CompressionFlags(0x7).is_known());
        assert!(!CompressionFlags(0x8).is_known());
    }

    #[test]
    fn values_round_trip_their_bytes() {
        let mut out = Vec::new();
        [1.5f64, -2.0, 0.25].put(&mut out);
        assert_eq!(out.len(), <[f64; 3]>::SIZE);
        assert_eq!(<[f64; 3]>::from_bytes(&out), [1.5, -2.0, 0.25]);
        let halves: Vec<u8> = [1.0f32, -0.5, 2.0]
            .iter()
            .flat_map(|&v| half::f16::from_f32(v).to_le_bytes())
            .collect();
        assert_eq!(<[f32; 3]>::from_half_bytes(&halves), [1.0, -0.5, 2.0]);
    }
}
