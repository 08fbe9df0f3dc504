//! Node values, the writer's side of [`crate::vdb::values`]: OpenVDB's node-value
//! compression, shared by internal nodes (one value per entry) and leaf buffers. With
//! [`CompressionFlags::ACTIVE_MASK`] a node stores its active values only, plus what it takes
//! to restore the inactive ones: a [`NodeMeta`] byte, up to two inactive values and a
//! selection mask.

use super::compress::write_chunk;
use crate::vdb::codec::{mask_is_on, CompressionFlags, NodeMeta, VdbValue};

/// OpenVDB's `writeCompressedValues`: metadata byte, the inactive values it needs, an
/// optional selection mask, then the stored values (zlib-compressed if asked).
pub(super) fn write_values<V: VdbValue>(
    out: &mut Vec<u8>,
    values: &[V],
    active: &[u64],
    children: Option<&[u64]>,
    background: V,
    flags: CompressionFlags,
) {
    let is_on = |n: usize| mask_is_on(active, n);
    let is_child = |n: usize| children.is_some_and(|c| mask_is_on(c, n));
    let mut stored: Vec<V> = Vec::with_capacity(values.len());
    if !flags.contains(CompressionFlags::ACTIVE_MASK) {
        out.push(NodeMeta::NoMaskAndAllVals as u8);
        stored.extend_from_slice(values);
    } else {
        // Classify the inactive values (child slots excluded), as MaskCompress does.
        let mut inactive = [background; 2];
        let mut unique = 0;
        for (n, v) in values.iter().enumerate() {
            if unique >= 3 {
                break;
            }
            if is_on(n) || is_child(n) {
                continue;
            }
            let seen = (unique > 0 && *v == inactive[0]) || (unique > 1 && *v == inactive[1]);
            if !seen {
                if unique < 2 {
                    inactive[unique] = *v;
                }
                unique += 1;
            }
        }
        let neg_bg = background.negate();
        let meta = match unique {
            0 => NodeMeta::NoMaskOrInactiveVals,
            1 if inactive[0] == background => NodeMeta::NoMaskOrInactiveVals,
            1 if inactive[0] == neg_bg => NodeMeta::NoMaskAndMinusBg,
            1 => NodeMeta::NoMaskAndOneInactiveVal,
            2 if inactive[0] != background && inactive[1] != background => {
                NodeMeta::MaskAndTwoInactiveVals
            }
            2 if inactive[1] == background => {
                if inactive[0] == neg_bg {
                    NodeMeta::MaskAndNoInactiveVals
                } else {
                    NodeMeta::MaskAndOneInactiveVal
                }
            }
            2 => {
                // inactive[0] is the background: the other value goes first.
                inactive.swap(0, 1);
                if inactive[0] == neg_bg {
                    NodeMeta::MaskAndNoInactiveVals
                } else {
                    NodeMeta::MaskAndOneInactiveVal
                }
            }
            _ => NodeMeta::NoMaskAndAllVals,
        };
        out.push(meta as u8);
        match meta {
            NodeMeta::NoMaskAndOneInactiveVal | NodeMeta::MaskAndOneInactiveVal => {
                inactive[0].put(out)
            }
            NodeMeta::MaskAndTwoInactiveVals => {
                inactive[0].put(out);
                inactive[1].put(out);
            }
            _ => {}
        }
        match meta {
            NodeMeta::NoMaskAndAllVals => stored.extend_from_slice(values),
            NodeMeta::NoMaskOrInactiveVals
            | NodeMeta::NoMaskAndMinusBg
            | NodeMeta::NoMaskAndOneInactiveVal => {
                stored.extend((0..values.len()).filter(|&n| is_on(n)).map(|n| values[n]));
            }
            NodeMeta::MaskAndNoInactiveVals
            | NodeMeta::MaskAndOneInactiveVal
            | NodeMeta::MaskAndTwoInactiveVals => {
                // Selection bit set where an inactive value equals inactive[1].
                let mut selection = vec![0u64; values.len().div_ceil(64)];
                for (n, v) in values.iter().enumerate() {
                    if is_on(n) {
                        stored.push(*v);
                    } else if *v == inactive[1] {
                        selection[n >> 6] |= 1 << (n & 63);
                    }
                }
                selection
                    .iter()
                    .for_each(|w| out.extend_from_slice(&w.to_le_bytes()));
            }
        }
    }
    let mut raw = Vec::with_capacity(stored.len() * V::SIZE);
    stored.iter().for_each(|v| v.put(&mut raw));
    write_chunk(out, &raw, flags);
}

#[cfg(test)]
mod tests {
    use super::*;

    fn classify(values: &[f32], active: &[u64], bg: f32) -> (u8, Vec<u8>) {
        let mut out = Vec::new();
        write_values(
            &mut out,
            values,
            active,
            None,
            bg,
            CompressionFlags::ACTIVE_MASK,
        );
        (out[0], out)
    }

    #[test]
    fn mask_compression_picks_the_openvdb_case() {
        let mut active = [0u64; 8];
        active[0] = 1; // voxel 0 active
        let bg = 2.0f32;
        let mut v = vec![bg; 512];
        v[0] = 7.0;
        assert_eq!(classify(&v, &active, bg).0, 0);
        let all_minus: Vec<f32> = (0..512).map(|n| if n == 0 { 7.0 } else { -bg }).collect();
        assert_eq!(classify(&all_minus, &active, bg).0, 1);
        let one_other: Vec<f32> = (0..512).map(|n| if n == 0 { 7.0 } else { 5.0 }).collect();
        let (m, bytes) = classify(&one_other, &active, bg);
        assert_eq!(m, 2);
        assert_eq!(&bytes[1..5], &5.0f32.to_le_bytes());
        let mut two = vec![bg; 512];
        two[0] = 7.0;
        two[3] = -bg;
        assert_eq!(classify(&two, &active, bg).0, 3);
        two[3] = 9.0;
        let (m, bytes) = classify(&two, &active, bg);
        assert_eq!(m, 4);
        assert_eq!(&bytes[1..5], &9.0f32.to_le_bytes());
        // 1 + 4 (value) + 64 (selection mask) + 4 (one active value)
        assert_eq!(bytes.len(), 73);
        two.iter_mut().skip(1).for_each(|x| *x = 9.0);
        two[5] = 11.0;
        assert_eq!(classify(&two, &active, bg).0, 5);
        two[6] = 12.0;
        let (m, bytes) = classify(&two, &active, bg);
        assert_eq!(m, 6);
        assert_eq!(bytes.len(), 1 + 512 * 4);
    }
}
