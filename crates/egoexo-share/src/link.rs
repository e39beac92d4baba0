//! Share links (`<page>#share=<id>.<key>[&t=<time>]`): the types are the protocol's
//! (`egoexo_protocol::share`, where the page reads them too); fresh keys are drawn here.

pub use egoexo_protocol::share::{LinkFragment, LinkTime, ShareId, ShareKey, ShareLink};

#[cfg(not(target_arch = "wasm32"))]
use crate::ShareError;

/// A fresh random key (native; the browser draws its keys with WebCrypto).
#[cfg(not(target_arch = "wasm32"))]
pub fn random_key() -> Result<ShareKey, ShareError> {
    let mut key = [0; 16];
    getrandom::fill(&mut key).map_err(|e| ShareError::Random(e.to_string()))?;
    Ok(ShareKey::from_bytes(key))
}
