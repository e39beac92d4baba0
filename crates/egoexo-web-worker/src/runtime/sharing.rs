//! Shares in the browser: what is shown is packed by [`SessionWorker`] and sealed (or opened)
//! with WebCrypto's AES-GCM in the layout of `egoexo_share::envelope`, under a key drawn with
//! `crypto.getRandomValues`; the key goes back to the page for the link and nowhere else.

use egoexo_protocol::JsBytes;
use egoexo_protocol::worker::{JobId, JobStage};
use egoexo_share::envelope;
use egoexo_share::{ShareError, ShareKey};
use js_sys::{Array, Uint8Array};
use wasm_bindgen::JsCast;
use wasm_bindgen::prelude::*;
use wasm_bindgen_futures::JsFuture;
use web_sys::{AesGcmParams, Crypto, CryptoKey, SubtleCrypto};

use super::{Event, Runtime, js_message};
use crate::worker::WorkerError;

impl Runtime {
    fn crypto(&self) -> Result<(Crypto, SubtleCrypto), WorkerError> {
        let crypto = self.scope.crypto().map_err(|e| ShareError::Random(js_message(&e)))?;
        let subtle = crypto.subtle();
        Ok((crypto, subtle))
    }

    /// Packs what is shown, seals it under a fresh key and posts `share-sealed`.
    pub(super) async fn create_share(&self, job: JobId, include_recording: bool) -> Result<(), WorkerError> {
        let stage = JobStage::Share;
        self.post(Event::Progress { job, stage, label: stage.label().into(), done: 0, total: 1 });
        let includes_recording = include_recording && self.worker.borrow().can_share_recording();
        let container = self.worker.borrow().pack_share(includes_recording, CREATED_BY)?;
        let (crypto, subtle) = self.crypto()?;
        let mut key = [0u8; 16];
        let mut iv = [0u8; envelope::IV_LEN];
        for buffer in [&mut key[..], &mut iv[..]] {
            crypto.get_random_values_with_u8_array(buffer).map_err(|e| ShareError::Random(js_message(&e)))?;
        }
        let aes = aes_gcm_key(&subtle, &key, "encrypt").await?;
        let params = aes_gcm_params(&iv, &envelope::header());
        let sealed = subtle
            .encrypt_with_object_and_u8_array(&params, &aes, &container)
            .map_err(|e| ShareError::Container(js_message(&e)))?;
        let ciphertext = JsFuture::from(sealed).await.map_err(|e| ShareError::Container(js_message(&e)))?;
        let ciphertext = Uint8Array::new(&ciphertext);
        let prefix = envelope::HEADER_LEN + envelope::IV_LEN;
        let sealed = Uint8Array::new_with_length((prefix + ciphertext.length() as usize) as u32);
        sealed.subarray(0, envelope::HEADER_LEN as u32).copy_from(&envelope::header());
        sealed.subarray(envelope::HEADER_LEN as u32, prefix as u32).copy_from(&iv);
        sealed.set(&ciphertext, prefix as u32);
        if self.stopped(job) {
            return Ok(());
        }
        self.post(Event::ShareSealed {
            job,
            sealed: JsBytes(sealed),
            key: ShareKey::from_bytes(key).encode(),
            includes_recording,
        });
        Ok(())
    }

    /// Opens a sealed share with the key from its link and posts `share-opened`.
    pub(super) async fn open_share(&self, job: JobId, sealed: &JsBytes, key: &str) -> Result<(), WorkerError> {
        let stage = JobStage::Share;
        self.post(Event::Progress { job, stage, label: stage.label().into(), done: 0, total: 1 });
        let key = ShareKey::decode(key).map_err(ShareError::Link)?;
        let bytes = sealed.to_vec();
        let parts = envelope::parse(&bytes)?;
        let (_, subtle) = self.crypto()?;
        let aes = aes_gcm_key(&subtle, key.as_bytes(), "decrypt").await?;
        let params = aes_gcm_params(&parts.iv, parts.header);
        let opened = subtle
            .decrypt_with_object_and_u8_array(&params, &aes, parts.ciphertext)
            .map_err(|_| ShareError::Decrypt)?;
        let container = JsFuture::from(opened).await.map_err(|_| ShareError::Decrypt)?;
        let opened = self.worker.borrow_mut().open_share(Uint8Array::new(&container).to_vec())?;
        if self.stopped(job) {
            return Ok(());
        }
        let manifest = opened.manifest;
        self.post(Event::ShareOpened {
            job,
            scene: JsBytes::copy_from(&opened.scene_json),
            summary: manifest.summary,
            session: manifest.session,
            includes_recording: manifest.includes_recording,
            created_by: manifest.created_by,
        });
        Ok(())
    }
}

/// What made a share, in its manifest.
const CREATED_BY: &str = concat!("egoexo ", env!("CARGO_PKG_VERSION"), " (page)");

/// A WebCrypto AES-GCM key for `usage` (`encrypt` or `decrypt`).
async fn aes_gcm_key(subtle: &SubtleCrypto, key: &[u8], usage: &str) -> Result<CryptoKey, WorkerError> {
    let usages = Array::of1(&JsValue::from_str(usage));
    let promise = subtle
        .import_key_with_str("raw", &Uint8Array::from(key), "AES-GCM", false, &usages)
        .map_err(|e| ShareError::Container(js_message(&e)))?;
    let key = JsFuture::from(promise).await.map_err(|e| ShareError::Container(js_message(&e)))?;
    key.dyn_into::<CryptoKey>().map_err(|_| ShareError::Container("WebCrypto gave no key".into()).into())
}

/// AES-GCM parameters: the IV, the envelope header as associated data, a 128-bit tag.
fn aes_gcm_params(iv: &[u8], header: &[u8]) -> AesGcmParams {
    let params = AesGcmParams::new("AES-GCM", &Uint8Array::from(iv));
    params.set_additional_data(&Uint8Array::from(header));
    params.set_tag_length((envelope::TAG_LEN * 8) as u8);
    params
}
