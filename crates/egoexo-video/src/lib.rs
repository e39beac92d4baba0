//! H.264 video in MP4 files, on in-memory bytes (no I/O; builds for wasm32).
//!
//! - [`demux`] reads an observer's recording: the first H.264 track's samples with their byte
//!   ranges, decode and presentation times, key frames, the `avcC` description and the codec
//!   string WebCodecs' `VideoDecoder` takes, and Annex B access units for native decoders.
//! - [`mux`] writes encoded frames into an MP4 (the page's video export, the simulator's
//!   observer videos).
//! - [`y4m`] writes raw YUV 4:2:0 video, what Chromium's fake camera plays in browser tests.
//!
//! Times are the track's own ticks (`timescale` per second); where a frame sits on the session
//! clock is the session's business (`egoexo_session::video`).

#[cfg(all(test, target_arch = "wasm32"))]
wasm_bindgen_test::wasm_bindgen_test_configure!(run_in_browser);

pub mod demux;
pub mod mux;
pub mod y4m;

pub use demux::{H264Track, VideoSample};
pub use mux::{EncodedFrame, avcc_record, h264_mp4, parameter_sets};

use thiserror::Error;

/// Why a video could not be read or written.
#[derive(Debug, Error)]
pub enum VideoError {
    #[error("the avcC description is not valid: {0}")]
    BadDescription(String),
    #[error("there are no frames to write")]
    NoFrames,
    #[error("frame 0 is not a key frame: a video must start with one")]
    NoLeadingKeyFrame,
    #[error("frame {index} has {got} bytes; expected {expected} (RGB, width × height × 3)")]
    BadFrame { index: usize, got: usize, expected: usize },
    #[error("frame {index} is empty")]
    EmptyFrame { index: usize },
    #[error("a video of {width}×{height} px cannot be written: each side must be even and 2..=8192 px")]
    BadSize { width: u32, height: u32 },
    #[error("frame rate {0} is not a rate in (0, 1000] frames per second")]
    BadFrameRate(f64),
    #[error("writing the MP4 failed: {0}")]
    Mux(#[from] mp4::Error),
    #[error("not a readable MP4 file: {0}")]
    NotMp4(String),
    #[error(
        "the MP4 has no H.264 video track (tracks: {found}); expected an `avc1` track as projectaria_tools' VRS-to-MP4 export writes"
    )]
    NoH264Track { found: String },
    #[error("the MP4 is fragmented (moof boxes); expected a plain MP4 with its sample tables in moov")]
    Fragmented,
    #[error("the H.264 track's sample tables are inconsistent: {0}")]
    BadSampleTables(String),
    #[error("sample {index} (bytes {offset}..{end}) lies outside the {file_len}-byte file")]
    SampleOutsideFile { index: usize, offset: u64, end: u64, file_len: usize },
    #[error("sample {index} is not a sequence of {length_size}-byte length-prefixed NAL units")]
    BadNalUnits { index: usize, length_size: u8 },
    #[error("the video is {width}×{height} px; expected each side in 1..=8192")]
    BadDimensions { width: u32, height: u32 },
}
