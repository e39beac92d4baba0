//! The page's reading and writing of its address fragment (`#share=<id>.<key>&t=12.5`,
//! `#sample&t=3-7`): the link format is `egoexo_protocol::share::LinkFragment`, defined once in
//! Rust for the page and the CLI alike.

use egoexo_protocol::live::LiveLink;
use egoexo_protocol::share::{LinkFragment, LinkTime, ShareId, ShareKey};
use serde::Serialize;
use wasm_bindgen::prelude::*;

#[derive(Serialize)]
struct ShareRef {
    id: String,
    key: String,
}

#[derive(Serialize)]
struct LiveRef {
    room: String,
    secret: String,
}

#[derive(Serialize)]
struct Fragment {
    share: Option<ShareRef>,
    /// A watch (or device) link's room: `#live=<room>.<secret>`.
    live: Option<LiveRef>,
    time: Option<LinkTime>,
    sample: bool,
}

fn parse(fragment: &str) -> Result<LinkFragment, JsError> {
    LinkFragment::parse(fragment).map_err(|e| JsError::new(&format!("the address is not a valid egoexo link: {e}")))
}

/// Reads a fragment (`location.hash`): `{share: {id, key} | null, live: {room, secret} |
/// null, time: {start, end} | null, sample}`. Throws, saying what is wrong, on a malformed
/// share or time.
#[wasm_bindgen]
pub fn parse_fragment(fragment: &str) -> Result<JsValue, JsError> {
    let parsed = parse(fragment)?;
    let value = Fragment {
        live: parsed.live.map(|link| LiveRef { room: link.room, secret: link.secret }),
        share: parsed.share.map(|(id, key)| ShareRef { id: id.to_string(), key: key.encode() }),
        time: parsed.time,
        sample: parsed.sample,
    };
    value.serialize(&serde_wasm_bindgen::Serializer::json_compatible()).map_err(|e| JsError::new(&e.to_string()))
}

/// The fragment of a live link (without `#`): `live=<room>.<secret>` — with the viewer secret
/// the page's watch link, with the device secret `xr.html`'s.
#[wasm_bindgen]
pub fn live_fragment(room: &str, secret: &str) -> String {
    LiveLink { room: room.to_string(), secret: secret.to_string() }.fragment()
}

/// `fragment` with its time set to `start` seconds (or the range `start`–`end`), or removed
/// when `start` is undefined; everything else in it is kept. Returns the new fragment
/// (without `#`).
#[wasm_bindgen]
pub fn fragment_with_time(fragment: &str, start: Option<f64>, end: Option<f64>) -> Result<String, JsError> {
    let mut parsed = parse(fragment).unwrap_or_default();
    parsed.time = match start {
        Some(start) if start.is_finite() && start >= 0.0 => {
            Some(LinkTime { start, end: end.filter(|e| e.is_finite() && *e > start) })
        }
        _ => None,
    };
    Ok(parsed.to_string())
}

/// The fragment of a share link (without `#`): `share=<id>.<key>`.
#[wasm_bindgen]
pub fn share_fragment(id: &str, key: &str) -> Result<String, JsError> {
    let id = ShareId::parse(id).map_err(|e| JsError::new(&e))?;
    let key = ShareKey::decode(key).map_err(|e| JsError::new(&e))?;
    Ok(LinkFragment { share: Some((id, key)), ..LinkFragment::default() }.to_string())
}

/// `link` as an SVG QR code (`crate::qr::qr_svg`): the Live panel shows the camera page's link
/// this way, for a phone to scan. Throws when the link is too long for any QR version.
#[wasm_bindgen]
pub fn link_qr_svg(link: &str) -> Result<String, JsError> {
    crate::qr::qr_svg(link).map_err(|e| JsError::new(&e.to_string()))
}
