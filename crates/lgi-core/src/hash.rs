//! A fast hash for the core's small integer keys (vertex and bundle indices, sets of a few
//! bundles), which no adversary chooses: the default SipHash cost about as much as the rest
//! of a missing-set plan's lookups of kept rows, and it sits in the surface-distance search's
//! inner loop.

use std::collections::HashMap;
use std::hash::{BuildHasherDefault, Hasher};

/// A `HashMap` with [`FastHasher`].
pub(crate) type FastMap<K, V> = HashMap<K, V, BuildHasherDefault<FastHasher>>;

/// Multiply-rotate hashing of each word written (the scheme of rustc's FxHash).
#[derive(Default)]
pub(crate) struct FastHasher(u64);

impl FastHasher {
    fn add(&mut self, x: u64) {
        self.0 = (self.0.rotate_left(5) ^ x).wrapping_mul(0x517c_c1b7_2722_0a95);
    }
}

impl Hasher for FastHasher {
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.add(u64::from(b));
        }
    }

    fn write_u32(&mut self, x: u32) {
        self.add(u64::from(x));
    }

    fn write_u64(&mut self, x: u64) {
        self.add(x);
    }

    fn write_usize(&mut self, x: usize) {
        self.add(x as u64);
    }

    fn finish(&self) -> u64 {
        self.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every key of a dense range is found again and no other: the map behaves as a map
    /// whatever the hash's quality.
    #[test]
    fn fast_map_holds_a_dense_range_of_vertex_keys() {
        let mut m: FastMap<u32, f64> = FastMap::default();
        for v in 0..50_000u32 {
            m.insert(v * 3, f64::from(v));
        }
        assert_eq!(m.len(), 50_000);
        for v in 0..50_000u32 {
            assert_eq!(m.get(&(v * 3)), Some(&f64::from(v)));
            assert_eq!(m.get(&(v * 3 + 1)), None);
        }
    }
}
