//! Uncompressed YUV4MPEG2 (`.y4m`) video, 4:2:0: what Chromium's fake camera plays
//! (`--use-fake-device-for-media-stream --use-file-for-fake-video-capture=<file>.y4m`), so a
//! browser test can film a rendered scene through `getUserMedia`.
//!
//! Frames go in as RGB (`width × height × 3` bytes, rows top to bottom) and are stored as
//! BT.601 limited-range Y′CbCr (what players assume of `C420`), chroma averaged
//! over each 2 × 2 block.

use crate::VideoError;

/// Appends Y4M to a byte buffer: the stream header once, then each frame.
#[derive(Debug)]
pub struct Y4mWriter {
    width: u32,
    height: u32,
    bytes: Vec<u8>,
    frames: usize,
}

impl Y4mWriter {
    /// A stream of `width × height` frames (even sides, 2..=8192) at `fps` (whole frames per
    /// second, 1..=1000).
    pub fn new(width: u32, height: u32, fps: u32) -> Result<Self, VideoError> {
        if width % 2 == 1 || height % 2 == 1 || !(2..=8192).contains(&width) || !(2..=8192).contains(&height) {
            return Err(VideoError::BadSize { width, height });
        }
        if !(1..=1000).contains(&fps) {
            return Err(VideoError::BadFrameRate(f64::from(fps)));
        }
        let bytes = format!("YUV4MPEG2 W{width} H{height} F{fps}:1 Ip A1:1 C420\n").into_bytes();
        Ok(Self { width, height, bytes, frames: 0 })
    }

    /// Appends one RGB frame.
    pub fn push_rgb(&mut self, rgb: &[u8]) -> Result<(), VideoError> {
        let (w, h) = (self.width as usize, self.height as usize);
        if rgb.len() != w * h * 3 {
            return Err(VideoError::BadFrame { index: self.frames, got: rgb.len(), expected: w * h * 3 });
        }
        self.bytes.extend_from_slice(b"FRAME\n");
        let pixel = |x: usize, y: usize| {
            let i = (y * w + x) * 3;
            [f32::from(rgb[i]), f32::from(rgb[i + 1]), f32::from(rgb[i + 2])]
        };
        let clamp = |v: f32| v.round().clamp(0.0, 255.0) as u8;
        for y in 0..h {
            for x in 0..w {
                let [r, g, b] = pixel(x, y);
                self.bytes.push(clamp(16.0 + 0.256_788 * r + 0.504_129 * g + 0.097_906 * b));
            }
        }
        let mut cb = Vec::with_capacity(w * h / 4);
        let mut cr = Vec::with_capacity(w * h / 4);
        for y in (0..h).step_by(2) {
            for x in (0..w).step_by(2) {
                let mut sum = [0.0f32; 3];
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let p = pixel(x + dx, y + dy);
                    for c in 0..3 {
                        sum[c] += 0.25 * p[c];
                    }
                }
                let [r, g, b] = sum;
                cb.push(clamp(128.0 - 0.148_223 * r - 0.290_993 * g + 0.439_216 * b));
                cr.push(clamp(128.0 + 0.439_216 * r - 0.367_788 * g - 0.071_427 * b));
            }
        }
        self.bytes.extend_from_slice(&cb);
        self.bytes.extend_from_slice(&cr);
        self.frames += 1;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The file's bytes; an error without any frame.
    pub fn finish(self) -> Result<Vec<u8>, VideoError> {
        if self.frames == 0 {
            return Err(VideoError::NoFrames);
        }
        Ok(self.bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_are_a_header_then_planes_of_limited_range_yuv_420() {
        let mut writer = Y4mWriter::new(4, 2, 30).unwrap();
        // Left half white, right half pure red.
        let mut rgb = Vec::new();
        for _ in 0..2 {
            for x in 0..4 {
                rgb.extend_from_slice(if x < 2 { &[255, 255, 255] } else { &[255, 0, 0] });
            }
        }
        writer.push_rgb(&rgb).unwrap();
        assert!(writer.push_rgb(&rgb[1..]).unwrap_err().to_string().contains("frame 1"));
        let bytes = writer.finish().unwrap();
        let header = b"YUV4MPEG2 W4 H2 F30:1 Ip A1:1 C420\nFRAME\n";
        assert_eq!(&bytes[..header.len()], header);
        let planes = &bytes[header.len()..];
        assert_eq!(planes.len(), 8 + 2 + 2);
        // White is Y 235, no chroma; red is Y 81, Cb 90, Cr 240 (BT.601).
        assert_eq!(&planes[..4], &[235, 235, 81, 81]);
        assert_eq!(&planes[8..], &[128, 90, 128, 240]);
        assert!(Y4mWriter::new(3, 2, 30).is_err() && Y4mWriter::new(4, 2, 0).is_err());
        assert!(matches!(Y4mWriter::new(2, 2, 30).unwrap().finish(), Err(VideoError::NoFrames)));
    }
}
