//! The protocols between egoexo's parts, typed once in Rust and documented in `docs/`:
//!
//! - [`worker`] — the page ↔ Web Worker messages (`docs/worker-protocol.md`): requests the
//!   page sends, events the worker answers with, error kinds the page reacts to, and the
//!   summaries it shows. Version [`worker::WORKER_PROTOCOL_VERSION`].
//! - [`share`] — the share API between the page (or the CLI) and the server
//!   (`docs/share-format.md`): share ids, expiries, answers and error kinds. Version
//!   [`share::SHARE_API_VERSION`].
//! - [`live`] — the live protocol between devices, the relay and viewers
//!   (`docs/live-protocol.md`): JSON control messages and compact binary data frames over the
//!   WebSocket subprotocol [`live::LIVE_SUBPROTOCOL`].
//!
//! Every message is plain serde data. Byte buffers are a type parameter `B`: natively (and in
//! tests) [`serde_bytes::ByteBuf`]; in the browser [`JsBytes`], the JS `Uint8Array` itself, so
//! a 100 MB session crosses from the page to the worker without being copied into and out of
//! the page's wasm memory. In the browser, messages are written with serde-wasm-bindgen and
//! read with `js::request_from_js` / `js::event_from_js`.

#[cfg(target_arch = "wasm32")]
pub mod js;
pub mod live;
pub mod share;
pub mod worker;

pub use serde_bytes::ByteBuf;

/// A JS `Uint8Array` inside a message: serialised as the same JS object
/// (`serde_wasm_bindgen::preserve`), so only `serde_wasm_bindgen` can write it; messages that
/// hold it are read with [`js`] (serde's tagged enums buffer their fields, which would copy
/// the array into wasm memory and lose the JS object).
#[cfg(target_arch = "wasm32")]
#[derive(Clone, Debug)]
pub struct JsBytes(pub js_sys::Uint8Array);

#[cfg(target_arch = "wasm32")]
impl JsBytes {
    /// A new `Uint8Array` holding a copy of `bytes`.
    pub fn copy_from(bytes: &[u8]) -> Self {
        JsBytes(js_sys::Uint8Array::from(bytes))
    }

    /// The bytes, copied into wasm memory.
    pub fn to_vec(&self) -> Vec<u8> {
        self.0.to_vec()
    }

    /// The `ArrayBuffer` behind the array (what a `postMessage` transfer list names).
    pub fn buffer(&self) -> js_sys::ArrayBuffer {
        self.0.buffer()
    }
}

#[cfg(target_arch = "wasm32")]
impl serde::Serialize for JsBytes {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serde_wasm_bindgen::preserve::serialize(&self.0, serializer)
    }
}
