//! The envelope a share is stored in, version [`ENVELOPE_VERSION`]:
//!
//! | bytes | content |
//! |---|---|
//! | 0–3 | magic `EGXS` |
//! | 4 | envelope version (1) |
//! | 5 | algorithm (1 = AES-128-GCM, 16-byte tag) |
//! | 6–17 | the 96-bit IV (random, fresh for every share) |
//! | 18– | ciphertext of the container, then the tag |
//!
//! Bytes 0–5 are the AEAD's associated data, so the header cannot be changed without the tag
//! failing. The key (128 random bits) is never in the envelope: it travels in the link.

use crate::ShareError;
#[cfg(not(target_arch = "wasm32"))]
use crate::link::ShareKey;

/// The first four bytes of every share.
pub const MAGIC: [u8; 4] = *b"EGXS";
/// The envelope's version.
pub const ENVELOPE_VERSION: u8 = 1;
/// AES-128-GCM with a 96-bit IV and a 128-bit tag.
pub const ALGORITHM_AES_128_GCM: u8 = 1;
/// Header length (the associated data).
pub const HEADER_LEN: usize = 6;
/// IV length.
pub const IV_LEN: usize = 12;
/// Tag length.
pub const TAG_LEN: usize = 16;

/// The header (and associated data) of an envelope of this version.
pub fn header() -> [u8; HEADER_LEN] {
    [MAGIC[0], MAGIC[1], MAGIC[2], MAGIC[3], ENVELOPE_VERSION, ALGORITHM_AES_128_GCM]
}

/// The parts of a sealed share.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SealedParts<'a> {
    /// The associated data (bytes 0–5).
    pub header: &'a [u8],
    pub iv: [u8; IV_LEN],
    /// Ciphertext followed by the tag.
    pub ciphertext: &'a [u8],
}

/// Splits a sealed share, checking the magic, version and algorithm.
pub fn parse(sealed: &[u8]) -> Result<SealedParts<'_>, ShareError> {
    if sealed.len() < MAGIC.len() || sealed[..MAGIC.len()] != MAGIC {
        return Err(ShareError::NotAShare);
    }
    if sealed.len() < HEADER_LEN + IV_LEN + TAG_LEN {
        return Err(ShareError::Truncated(sealed.len()));
    }
    if sealed[4] != ENVELOPE_VERSION {
        return Err(ShareError::EnvelopeVersion(sealed[4]));
    }
    if sealed[5] != ALGORITHM_AES_128_GCM {
        return Err(ShareError::Algorithm(sealed[5]));
    }
    let mut iv = [0; IV_LEN];
    iv.copy_from_slice(&sealed[HEADER_LEN..HEADER_LEN + IV_LEN]);
    Ok(SealedParts { header: &sealed[..HEADER_LEN], iv, ciphertext: &sealed[HEADER_LEN + IV_LEN..] })
}

/// A sealed share from its IV and the AEAD's output (ciphertext and tag).
pub fn assemble(iv: &[u8; IV_LEN], ciphertext_and_tag: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + IV_LEN + ciphertext_and_tag.len());
    out.extend_from_slice(&header());
    out.extend_from_slice(iv);
    out.extend_from_slice(ciphertext_and_tag);
    out
}

/// A fresh random IV.
#[cfg(not(target_arch = "wasm32"))]
pub fn random_iv() -> Result<[u8; IV_LEN], ShareError> {
    let mut iv = [0; IV_LEN];
    getrandom::fill(&mut iv).map_err(|e| ShareError::Random(e.to_string()))?;
    Ok(iv)
}

/// Seals container bytes under `key` with the IV `iv` (use [`random_iv`]; never reuse one).
#[cfg(not(target_arch = "wasm32"))]
pub fn seal(key: &ShareKey, iv: &[u8; IV_LEN], plaintext: &[u8]) -> Result<Vec<u8>, ShareError> {
    use aes_gcm::aead::{Aead, KeyInit, Payload};
    let cipher = aes_gcm::Aes128Gcm::new(&(*key.as_bytes()).into());
    let ciphertext = cipher
        .encrypt(&(*iv).into(), Payload { msg: plaintext, aad: &header() })
        .map_err(|_| ShareError::Container("the share is too large to encrypt".into()))?;
    Ok(assemble(iv, &ciphertext))
}

/// Opens a sealed share with `key`; a wrong key or any changed byte is [`ShareError::Decrypt`].
#[cfg(not(target_arch = "wasm32"))]
pub fn open(key: &ShareKey, sealed: &[u8]) -> Result<Vec<u8>, ShareError> {
    use aes_gcm::aead::{Aead, KeyInit, Payload};
    let parts = parse(sealed)?;
    let cipher = aes_gcm::Aes128Gcm::new(&(*key.as_bytes()).into());
    cipher
        .decrypt(&parts.iv.into(), Payload { msg: parts.ciphertext, aad: parts.header })
        .map_err(|_| ShareError::Decrypt)
}

#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    #[test]
    fn seal_then_open_and_every_tampering_fails() {
        let key = crate::link::random_key().unwrap();
        let iv = random_iv().unwrap();
        let sealed = seal(&key, &iv, b"the container").unwrap();
        assert_eq!(&sealed[..4], b"EGXS");
        assert_eq!(sealed.len(), HEADER_LEN + IV_LEN + b"the container".len() + TAG_LEN);
        assert_eq!(open(&key, &sealed).unwrap(), b"the container");
        for i in [3, 4, 5, 6, 20, sealed.len() - 1] {
            let mut bad = sealed.clone();
            bad[i] ^= 1;
            assert!(open(&key, &bad).is_err(), "byte {i} changed");
        }
        let other = crate::link::random_key().unwrap();
        assert!(matches!(open(&other, &sealed), Err(ShareError::Decrypt)));
        assert!(matches!(open(&key, b"PK\x03\x04"), Err(ShareError::NotAShare)));
        assert!(matches!(open(&key, &sealed[..20]), Err(ShareError::Truncated(20))));
    }

    #[test]
    fn a_known_vector_pins_the_layout() {
        // NIST SP 800-38D test case 2 (AES-128, zero key and IV, one zero block, no AAD)
        // checks the cipher; our AAD is the header, so the tag differs from the NIST one.
        use aes_gcm::aead::{Aead, KeyInit};
        let cipher = aes_gcm::Aes128Gcm::new(&[0u8; 16].into());
        let out = cipher.encrypt(&[0u8; 12].into(), &[0u8; 16][..]).unwrap();
        let hex: String = out.iter().map(|b| format!("{b:02x}")).collect();
        assert_eq!(hex, "0388dace60b6a392f328c2b971b2fe78ab6e47d42cec13bdf53a67b21257bddf");
        let sealed = seal(&ShareKey::from_bytes([0; 16]), &[0; 12], &[0; 16]).unwrap();
        assert_eq!(&sealed[HEADER_LEN + IV_LEN..HEADER_LEN + IV_LEN + 16], &out[..16]);
        assert_ne!(&sealed[HEADER_LEN + IV_LEN + 16..], &out[16..], "the header is authenticated");
    }
}
