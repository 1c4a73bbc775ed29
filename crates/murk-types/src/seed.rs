//! The one seed derivation of murk: `(master seed, item key, purpose)` →
//! the seed of that item's random draws.
//!
//! Every randomised step of fit, infer, diagnose and the CLI derives its
//! seed here from the user's master seed, the *name* of the item it works
//! on (a scan's path, an image's file name, a weather class, a test's
//! observable and covariate) and the [`Purpose`] of the draws. Because the
//! key is a name and not a position, an item's draws do not depend on the
//! order of a batch or on which rayon thread takes it, and two purposes
//! never share a stream.
//!
//! The derivation is SHA-256 over `tag ‖ seed ‖ len(key) ‖ key`, with the
//! purpose's [`Purpose::tag`] (no tag is a prefix of another, so the input
//! is read back unambiguously), the seed as 8 little-endian bytes and the
//! key's byte length as 8 little-endian bytes. The 32-byte digest keys a
//! ChaCha generator directly ([`DerivedSeed::bytes`]) or gives a `u64` seed
//! ([`DerivedSeed::to_u64`], its first 8 bytes, little-endian).
//!
//! A key made of several names is built with [`key`], which length-prefixes
//! each part so that `("a/b", "c")` and `("a", "b/c")` stay apart.
//!
//! The campaign generator (murk-fixtures) keeps its own streams on purpose:
//! it plays the world the model is checked against, so it shares no draw
//! with the model's simulation (see `fixtures/src/math.rs`).
//!
//! ```
//! use murk_types::seed::{self, Purpose};
//!
//! let a = seed::derive(7, "scans/0001.pcd", Purpose::ApplyScan);
//! assert_eq!(a, seed::derive(7, "scans/0001.pcd", Purpose::ApplyScan));
//! assert_ne!(a, seed::derive(7, "scans/0002.pcd", Purpose::ApplyScan));
//! assert_ne!(a, seed::derive(8, "scans/0001.pcd", Purpose::ApplyScan));
//! assert_ne!(a.to_u64(), seed::derive(7, "scans/0001.pcd", Purpose::RainImage).to_u64());
//! assert_eq!(seed::key(&["test", "survival", "Road state"]), "4:test8:survival10:Road state");
//! ```

use sha2::{Digest, Sha256};

/// What a derived seed is used for. Each purpose is its own family of
/// streams: the same master seed and key give unrelated draws under two
/// purposes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum Purpose {
    /// murk-infer: every draw of one applied scan (key: the scan's path
    /// relative to the batch input). Within the scan, murk-infer splits the
    /// generator into streams per step and chunk.
    ApplyScan,
    /// murk-fit: the bootstrap over recordings of one no-change rate (key:
    /// `"lidar/<class>"` or `"radar/<class>"`).
    Bootstrap,
    /// murk-diagnose: the split of recordings into folds (key: `"folds"`).
    DiagnoseFolds,
    /// murk-diagnose: the master seed of the held-out simulations (key:
    /// `"simulate"`), passed on to murk-infer as its seed.
    DiagnoseSimulate,
    /// murk-diagnose: the permutations of one test (key: observable and
    /// covariate(s), see [`key`]).
    DiagnoseTest,
    /// `murk rain`: the drops of one image (key: the image's file name).
    RainImage,
}

impl Purpose {
    /// Every purpose.
    pub const ALL: [Purpose; 6] = [
        Purpose::ApplyScan,
        Purpose::Bootstrap,
        Purpose::DiagnoseFolds,
        Purpose::DiagnoseSimulate,
        Purpose::DiagnoseTest,
        Purpose::RainImage,
    ];

    /// The domain tag hashed before the seed. `ApplyScan`'s is the tag
    /// murk-infer has always used, so applied scans keep their bytes.
    pub fn tag(self) -> &'static str {
        match self {
            Purpose::ApplyScan => "murk-infer/1",
            Purpose::Bootstrap => "murk-fit/bootstrap/1",
            Purpose::DiagnoseFolds => "murk-diagnose/folds/1",
            Purpose::DiagnoseSimulate => "murk-diagnose/simulate/1",
            Purpose::DiagnoseTest => "murk-diagnose/test/1",
            Purpose::RainImage => "murk-rain/image/1",
        }
    }
}

/// A derived seed: 32 bytes of SHA-256.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DerivedSeed([u8; 32]);

impl DerivedSeed {
    /// The 32 bytes, e.g. the key of a ChaCha generator
    /// (`ChaCha8Rng::from_seed`).
    pub fn bytes(self) -> [u8; 32] {
        self.0
    }

    /// A 64-bit seed: the first 8 bytes, little-endian (e.g. for
    /// `SeedableRng::seed_from_u64` or a library's `seed(u64)` setter).
    pub fn to_u64(self) -> u64 {
        u64::from_le_bytes(self.0[..8].try_into().expect("8 of 32 bytes"))
    }
}

/// The seed of item `key` for `purpose` under master `seed` (see the module
/// docs for the exact bytes hashed).
pub fn derive(seed: u64, key: &str, purpose: Purpose) -> DerivedSeed {
    let mut h = Sha256::new();
    h.update(purpose.tag().as_bytes());
    h.update(seed.to_le_bytes());
    h.update((key.len() as u64).to_le_bytes());
    h.update(key.as_bytes());
    DerivedSeed(h.finalize().into())
}

/// One key from several names, each written as `len:name` (its byte
/// length in decimal, a colon, the name), so no two lists of names give the
/// same key.
pub fn key(parts: &[&str]) -> String {
    let mut k = String::new();
    for p in parts {
        k.push_str(&p.len().to_string());
        k.push(':');
        k.push_str(p);
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_tag_is_a_prefix_of_another() {
        for a in Purpose::ALL {
            for b in Purpose::ALL {
                if a != b {
                    assert!(!b.tag().starts_with(a.tag()), "{a:?} / {b:?}");
                }
            }
        }
    }

    /// Known answer, computed independently of this code: `printf` the
    /// bytes and pipe them through `sha256sum`:
    /// `printf 'murk-infer/1\x07\0\0\0\0\0\0\0\x03\0\0\0\0\0\0\0abc' | sha256sum`.
    #[test]
    fn digest_is_sha256_of_tag_seed_length_and_key() {
        let d = derive(7, "abc", Purpose::ApplyScan).bytes();
        let hex: String = d.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(hex, KNOWN_APPLY_7_ABC);
        assert_eq!(
            derive(7, "abc", Purpose::ApplyScan).to_u64(),
            u64::from_le_bytes(d[..8].try_into().unwrap())
        );
    }

    const KNOWN_APPLY_7_ABC: &str =
        "0f4b5e34e28ef8dc4818a9381bf411c34b41c4d8d54b3ec35911c93f73c1ee22";

    #[test]
    fn multi_part_keys_do_not_collide() {
        assert_ne!(key(&["a/b", "c"]), key(&["a", "b/c"]));
        assert_ne!(key(&["ab", ""]), key(&["a", "b"]));
        assert_ne!(key(&["1:a"]), key(&["", "a"]));
    }

    #[test]
    fn purposes_seeds_and_keys_each_change_the_seed() {
        let base = derive(1, "k", Purpose::Bootstrap);
        assert_ne!(base, derive(2, "k", Purpose::Bootstrap));
        assert_ne!(base, derive(1, "l", Purpose::Bootstrap));
        for p in Purpose::ALL {
            if p != Purpose::Bootstrap {
                assert_ne!(base, derive(1, "k", p), "{p:?}");
            }
        }
    }
}
