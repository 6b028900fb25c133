//! SHA-256 digests as hex text: whole (file and mesh identities in manifests)
//! or short (16 hex digits: configuration and stage digests in stamps and
//! level-file metadata).

use sha2::{Digest, Sha256};

/// Hex of all 32 bytes of the SHA-256 of `parts`, each followed by a zero
/// byte when `separated` (so ("ab", "c") and ("a", "bc") differ).
fn sha256_hex(parts: &[&[u8]], separated: bool, bytes: usize) -> String {
    let mut h = Sha256::new();
    for p in parts {
        h.update(p);
        if separated {
            h.update([0u8]);
        }
    }
    hex(&h.finalize()[..bytes])
}

/// Lower-case hex of `bytes` (a finished digest).
pub fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Full SHA-256 of `bytes`, 64 hex digits.
pub fn sha256(bytes: &[u8]) -> String {
    sha256_hex(&[bytes], false, 32)
}

/// Short digest of `text`: the first 8 bytes of its SHA-256, 16 hex digits.
pub fn short(text: &str) -> String {
    sha256_hex(&[text.as_bytes()], false, 8)
}

/// Short digest of several strings, each one delimited.
pub fn short_of_parts(parts: &[&str]) -> String {
    let bytes: Vec<&[u8]> = parts.iter().map(|p| p.as_bytes()).collect();
    sha256_hex(&bytes, true, 8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn digests_are_sha256() {
        // FIPS 180-2 test vector.
        assert_eq!(sha256(b"abc"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
        assert_eq!(short("abc"), "ba7816bf8f01cfea");
        assert_ne!(short_of_parts(&["ab", "c"]), short_of_parts(&["a", "bc"]));
        assert_eq!(short_of_parts(&["abc"]).len(), 16);
    }
}
