//! Native H.264 decoding and encoding with OpenH264 (BSD-2-Clause; the `openh264` crate
//! compiles it from source, so the CLI needs no system library and no download). Used by
//! `egoexo keypoints` / `egoexo reconstruct` to decode observers' videos, and by the simulator
//! to encode the observer videos it renders.
//!
//! OpenH264 decodes the Constrained Baseline and (without B-frames) Main/High streams; a
//! video whose frames are reordered (B-frames) is refused with a message saying to re-export
//! it without them (the browser's WebCodecs decoder takes both).

use egoexo_video::{EncodedFrame, H264Track, VideoError, avcc_record, h264_mp4};
use openh264::decoder::Decoder;
use openh264::encoder::{Encoder, EncoderConfig};
use openh264::formats::{RgbSliceU8, YUVBuffer, YUVSource};
use thiserror::Error;

/// Why a video could not be decoded or encoded natively.
#[derive(Debug, Error)]
pub enum CodecError {
    #[error("OpenH264 decoder: {0}")]
    Decoder(String),
    #[error("OpenH264 encoder: {0}")]
    Encoder(String),
    #[error(
        "the video reorders frames (B-frames), which the native decoder (OpenH264) cannot decode; re-export it without B-frames (e.g. ffmpeg -c:v libx264 -bf 0) or open the session in the page"
    )]
    Reordered,
    #[error("decoded frame {index} is {got_w}×{got_h} px, the track says {width}×{height}")]
    FrameSize { index: usize, got_w: usize, got_h: usize, width: u32, height: u32 },
    #[error("frame {index} has {got} bytes, expected {width}×{height}×3 RGB")]
    BadRgb { index: usize, got: usize, width: u32, height: u32 },
    #[error(transparent)]
    Video(#[from] VideoError),
}

/// Decodes every frame of `track` out of `mp4` and hands each to `frame(index, rgb)` in
/// presentation order (`index` counts frames in that order; `rgb` is `width × height × 3`
/// bytes, rows top to bottom). `frame` returns `false` to stop early (cancel).
pub fn decode_frames(
    track: &H264Track,
    mp4: &[u8],
    mut frame: impl FnMut(usize, &[u8]) -> bool,
) -> Result<usize, CodecError> {
    let order = track.presentation_order();
    if order.iter().enumerate().any(|(i, &s)| i != s) {
        return Err(CodecError::Reordered);
    }
    let mut decoder = Decoder::new().map_err(|e| CodecError::Decoder(e.to_string()))?;
    let (w, h) = (track.width as usize, track.height as usize);
    let mut rgb = vec![0u8; w * h * 3];
    let mut emitted = 0usize;
    let mut emit =
        |yuv: &openh264::decoder::DecodedYUV<'_>, rgb: &mut Vec<u8>, emitted: &mut usize| -> Result<bool, CodecError> {
            let (gw, gh) = yuv.dimensions();
            if (gw, gh) != (w, h) {
                return Err(CodecError::FrameSize {
                    index: *emitted,
                    got_w: gw,
                    got_h: gh,
                    width: track.width,
                    height: track.height,
                });
            }
            yuv.write_rgb8(rgb);
            let go_on = frame(*emitted, rgb);
            *emitted += 1;
            Ok(go_on)
        };
    for sample in 0..track.samples.len() {
        let access_unit = track.annex_b(mp4, sample)?;
        let decoded = decoder.decode(&access_unit).map_err(|e| CodecError::Decoder(format!("sample {sample}: {e}")))?;
        if let Some(yuv) = decoded
            && !emit(&yuv, &mut rgb, &mut emitted)?
        {
            return Ok(emitted);
        }
    }
    for yuv in decoder.flush_remaining().map_err(|e| CodecError::Decoder(e.to_string()))? {
        if !emit(&yuv, &mut rgb, &mut emitted)? {
            break;
        }
    }
    Ok(emitted)
}

/// Encodes RGB frames (`width × height × 3` bytes each, even sides) with OpenH264 into an MP4
/// playing at `fps` at about `bitrate_bps`, a key frame every 30 frames.
pub fn encode_mp4(
    frames: impl IntoIterator<Item = impl AsRef<[u8]>>,
    width: u32,
    height: u32,
    fps: f64,
    bitrate_bps: u32,
) -> Result<Vec<u8>, CodecError> {
    use openh264::encoder::{BitRate, FrameRate, IntraFramePeriod};
    let config = EncoderConfig::new()
        .bitrate(BitRate::from_bps(bitrate_bps))
        .max_frame_rate(FrameRate::from_hz(fps as f32))
        .skip_frames(false)
        .intra_frame_period(IntraFramePeriod::from_num_frames(30));
    let api = openh264::OpenH264API::from_source();
    let mut encoder = Encoder::with_api_config(api, config).map_err(|e| CodecError::Encoder(e.to_string()))?;
    let (mut sps, mut pps) = (None::<Vec<u8>>, None::<Vec<u8>>);
    let mut encoded = Vec::new();
    for (index, rgb) in frames.into_iter().enumerate() {
        let rgb = rgb.as_ref();
        if rgb.len() != width as usize * height as usize * 3 {
            return Err(CodecError::BadRgb { index, got: rgb.len(), width, height });
        }
        let yuv = YUVBuffer::from_rgb8_source(RgbSliceU8::new(rgb, (width as usize, height as usize)));
        debug_assert_eq!(yuv.dimensions(), (width as usize, height as usize));
        let stream = encoder.encode(&yuv).map_err(|e| CodecError::Encoder(format!("frame {index}: {e}")))?;
        let annex_b = stream.to_vec();
        let mut data = Vec::with_capacity(annex_b.len());
        let mut key = false;
        for unit in openh264::nal_units(&annex_b) {
            let unit = strip_start_code(unit);
            let Some(&header) = unit.first() else { continue };
            match header & 0x1f {
                7 => sps = sps.or_else(|| Some(unit.to_vec())),
                8 => pps = pps.or_else(|| Some(unit.to_vec())),
                kind => {
                    key |= kind == 5;
                    data.extend_from_slice(&(unit.len() as u32).to_be_bytes());
                    data.extend_from_slice(unit);
                }
            }
        }
        if !data.is_empty() {
            encoded.push(EncodedFrame { key, data });
        }
    }
    let (Some(sps), Some(pps)) = (sps, pps) else {
        return Err(CodecError::Encoder("no parameter sets came out (no frames?)".into()));
    };
    Ok(h264_mp4(&avcc_record(&sps, &pps)?, width, height, fps, &encoded)?)
}

/// A NAL unit without its Annex B start code (`00 00 01` or `00 00 00 01`).
fn strip_start_code(unit: &[u8]) -> &[u8] {
    let zeros = unit.iter().take_while(|&&b| b == 0).count();
    if zeros >= 2 && unit.get(zeros) == Some(&1) { &unit[zeros + 1..] } else { unit }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A moving gradient: each frame differs, so the codec has something to do.
    fn frame(i: usize, w: usize, h: usize) -> Vec<u8> {
        let mut rgb = vec![0u8; w * h * 3];
        for y in 0..h {
            for x in 0..w {
                let p = (y * w + x) * 3;
                rgb[p] = ((x + 3 * i) % 256) as u8;
                rgb[p + 1] = ((y * 2) % 256) as u8;
                rgb[p + 2] = if (x / 16 + y / 16 + i / 4).is_multiple_of(2) { 220 } else { 30 };
            }
        }
        rgb
    }

    #[test]
    fn encoded_frames_decode_back_close_to_the_input_in_order() {
        let (w, h) = (96usize, 64usize);
        let frames: Vec<Vec<u8>> = (0..40).map(|i| frame(i, w, h)).collect();
        let mp4 = encode_mp4(frames.iter().map(Vec::as_slice), w as u32, h as u32, 30.0, 2_000_000).unwrap();
        let track = H264Track::read(&mp4).unwrap();
        assert_eq!(track.samples.len(), 40);
        assert!(track.samples[0].key);
        let mut errors = Vec::new();
        let n = decode_frames(&track, &mp4, |i, rgb| {
            let mean_abs: f64 =
                rgb.iter().zip(&frames[i]).map(|(&a, &b)| f64::from(a.abs_diff(b))).sum::<f64>() / rgb.len() as f64;
            // Against the neighbours too: the frame must be closest to its own input.
            let others = [i.saturating_sub(2), (i + 2).min(39)]
                .iter()
                .filter(|&&j| j != i)
                .map(|&j| {
                    rgb.iter().zip(&frames[j]).map(|(&a, &b)| f64::from(a.abs_diff(b))).sum::<f64>() / rgb.len() as f64
                })
                .fold(f64::INFINITY, f64::min);
            errors.push((mean_abs, others));
            true
        })
        .unwrap();
        assert_eq!(n, 40);
        for (i, (own, other)) in errors.iter().enumerate() {
            assert!(*own < 8.0 && own < other, "frame {i}: {own:.1} against its input, {other:.1} against a neighbour");
        }
        // Cancelling stops the decoding.
        assert_eq!(decode_frames(&track, &mp4, |i, _| i < 9).unwrap(), 10);
    }
}
