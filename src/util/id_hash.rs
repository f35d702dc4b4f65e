//! A fast hasher for integer ids (COLMAP camera, image and point ids).
//!
//! SipHash (std's default) guards against adversarial keys at several times the cost per lookup;
//! id maps of a million points are built and probed on every model load, and a hostile file can
//! at worst slow its own load down, so a multiply-rotate combine with MurmurHash3's finaliser is
//! used instead.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// Multiply-rotate hasher for integer keys.
#[derive(Default, Clone, Copy)]
pub struct IdHasher {
    hash: u64,
}

const SEED: u64 = 0x51_7c_c1_b7_27_22_0a_95;

impl Hasher for IdHasher {
    fn finish(&self) -> u64 {
        // MurmurHash3's 64-bit finaliser: every input bit reaches the top bits, which hashbrown
        // uses as its probe tags.
        let mut h = self.hash;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h = h.wrapping_mul(0xc4ce_b9fe_1a85_ec53);
        h ^ (h >> 33)
    }

    fn write(&mut self, bytes: &[u8]) {
        for chunk in bytes.chunks(8) {
            let mut word = [0u8; 8];
            word[..chunk.len()].copy_from_slice(chunk);
            self.write_u64(u64::from_le_bytes(word));
        }
    }

    fn write_u32(&mut self, value: u32) {
        self.write_u64(value as u64);
    }

    fn write_u64(&mut self, value: u64) {
        self.hash = (self.hash.rotate_left(5) ^ value).wrapping_mul(SEED);
    }

    fn write_usize(&mut self, value: usize) {
        self.write_u64(value as u64);
    }
}

/// A `HashMap` keyed by integer ids.
pub type IdMap<K, V> = HashMap<K, V, BuildHasherDefault<IdHasher>>;

/// An empty id map with room for `capacity` entries.
pub fn id_map_with_capacity<K, V>(capacity: usize) -> IdMap<K, V> {
    IdMap::with_capacity_and_hasher(capacity, BuildHasherDefault::default())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn distinct_ids_spread_over_buckets() {
        let mut map: IdMap<u64, usize> = id_map_with_capacity(10);
        for i in 0..100_000u64 {
            map.insert(i * 7 + 100, i as usize);
        }
        assert_eq!(map.len(), 100_000);
        assert_eq!(map[&(7 * 500 + 100)], 500);
        let low_bits: std::collections::HashSet<u64> = (0..1024u64)
            .map(|i| {
                let mut h = IdHasher::default();
                h.write_u64(i);
                h.finish() >> 54
            })
            .collect();
        assert!(
            low_bits.len() > 500,
            "top bits poorly spread: {}",
            low_bits.len()
        );
    }
}
