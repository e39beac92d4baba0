//! `mux_h264_mp4`: the page's video export hands the frames its `VideoEncoder` produced to
//! [`egoexo_video::h264_mp4`] and downloads the MP4 it returns.

use wasm_bindgen::prelude::*;

use egoexo_video::{EncodedFrame, h264_mp4};

/// Writes an MP4 file: `avcc` is the encoder's `decoderConfig.description` (H.264 in AVC
/// format), `data` every encoded frame's bytes back to back in decode order, `sizes` each
/// frame's byte count and `keys` whether it is a key frame (1) or not (0); the video is
/// `width × height` pixels at `fps`. Throws an `Error` saying what was wrong.
#[wasm_bindgen]
pub fn mux_h264_mp4(
    avcc: &[u8],
    width: u32,
    height: u32,
    fps: f64,
    data: &[u8],
    sizes: &[u32],
    keys: &[u8],
) -> Result<js_sys::Uint8Array, JsError> {
    if sizes.len() != keys.len() {
        return Err(JsError::new(&format!("{} frame sizes but {} key flags", sizes.len(), keys.len())));
    }
    let total: u64 = sizes.iter().map(|&s| u64::from(s)).sum();
    if total != data.len() as u64 {
        return Err(JsError::new(&format!("the frame sizes add up to {total} bytes, the data has {}", data.len())));
    }
    let mut at = 0usize;
    let frames: Vec<EncodedFrame> = sizes
        .iter()
        .zip(keys)
        .map(|(&size, &key)| {
            let frame = EncodedFrame { key: key != 0, data: data[at..at + size as usize].to_vec() };
            at += size as usize;
            frame
        })
        .collect();
    let bytes = h264_mp4(avcc, width, height, fps, &frames).map_err(|e| JsError::new(&e.to_string()))?;
    Ok(js_sys::Uint8Array::from(bytes.as_slice()))
}
