//! Writing H.264 into MP4: frames encoded in AVC format (length-prefixed NAL units, the
//! stream's parameter sets in an `avcC` description) — the page's WebCodecs `VideoEncoder`
//! (the video export) or a native encoder (the simulator's observer videos) — written into an
//! MP4 file (the `mp4` crate) at a fixed frame rate.
//!
//! Times come from frame indices, not from the encoder's microsecond timestamps, so a
//! 29.97 fps session stays exact: the track's timescale is `1000 × fps` (rounded) and every
//! frame lasts 1000 ticks.

use std::io::Cursor;

use crate::VideoError;

/// One encoded frame, in decode order (WebCodecs' `EncodedVideoChunk`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct EncodedFrame {
    /// A key frame (IDR): decoding can start here.
    pub key: bool,
    /// Length-prefixed NAL units (AVC format).
    pub data: Vec<u8>,
}

/// The first sequence and picture parameter sets (SPS, PPS) of an `avcC` record
/// (ISO/IEC 14496-15 § 5.3.3.1).
pub fn parameter_sets(avcc: &[u8]) -> Result<(Vec<u8>, Vec<u8>), VideoError> {
    let bad = |what: &str| VideoError::BadDescription(format!("{what} ({} bytes)", avcc.len()));
    if avcc.len() < 7 || avcc[0] != 1 {
        return Err(bad("expected an AVCDecoderConfigurationRecord, version 1"));
    }
    let mut at = 5;
    let read_sets = |at: &mut usize, count: usize, what: &str| -> Result<Vec<Vec<u8>>, VideoError> {
        let mut sets = Vec::with_capacity(count);
        for _ in 0..count {
            let len = avcc.get(*at..*at + 2).map(|b| usize::from(u16::from_be_bytes([b[0], b[1]])));
            let set = len.and_then(|len| avcc.get(*at + 2..*at + 2 + len));
            let set = set.ok_or_else(|| bad(&format!("a {what} runs past the end")))?;
            *at += 2 + set.len();
            sets.push(set.to_vec());
        }
        Ok(sets)
    };
    let sps_count = usize::from(avcc[at] & 0x1f);
    at += 1;
    let sps = read_sets(&mut at, sps_count, "sequence parameter set")?;
    let pps_count = usize::from(*avcc.get(at).ok_or_else(|| bad("no picture parameter set count"))?);
    at += 1;
    let pps = read_sets(&mut at, pps_count, "picture parameter set")?;
    match (sps.into_iter().next(), pps.into_iter().next()) {
        (Some(sps), Some(pps)) if sps.len() >= 4 && !pps.is_empty() => Ok((sps, pps)),
        _ => Err(bad("expected at least one SPS and one PPS")),
    }
}

/// An `AVCDecoderConfigurationRecord` (ISO/IEC 14496-15 § 5.3.3.1) for one SPS and one PPS
/// (NAL units without start codes), NAL unit lengths of 4 bytes — the inverse of
/// [`parameter_sets`], for encoders that emit parameter sets in band (Annex B).
pub fn avcc_record(sps: &[u8], pps: &[u8]) -> Result<Vec<u8>, VideoError> {
    if sps.len() < 4 || pps.is_empty() || sps.len() > 0xffff || pps.len() > 0xffff {
        return Err(VideoError::BadDescription(format!("an SPS of {} and a PPS of {} bytes", sps.len(), pps.len())));
    }
    let mut v = vec![1, sps[1], sps[2], sps[3], 0xff, 0xe1];
    v.extend_from_slice(&(sps.len() as u16).to_be_bytes());
    v.extend_from_slice(sps);
    v.push(1);
    v.extend_from_slice(&(pps.len() as u16).to_be_bytes());
    v.extend_from_slice(pps);
    Ok(v)
}

/// Writes `frames` (decode order, starting with a key frame) of an H.264 stream described by
/// `avcc`, `width × height` pixels, as an MP4 file playing at `fps`.
pub fn h264_mp4(
    avcc: &[u8],
    width: u32,
    height: u32,
    fps: f64,
    frames: &[EncodedFrame],
) -> Result<Vec<u8>, VideoError> {
    if !(2..=8192).contains(&width) || !(2..=8192).contains(&height) || width % 2 == 1 || height % 2 == 1 {
        return Err(VideoError::BadSize { width, height });
    }
    if !(fps.is_finite() && fps > 0.0 && fps <= 1000.0) {
        return Err(VideoError::BadFrameRate(fps));
    }
    let first = frames.first().ok_or(VideoError::NoFrames)?;
    if !first.key {
        return Err(VideoError::NoLeadingKeyFrame);
    }
    if let Some(index) = frames.iter().position(|f| f.data.is_empty()) {
        return Err(VideoError::EmptyFrame { index });
    }
    let (seq_param_set, pic_param_set) = parameter_sets(avcc)?;
    const TICKS_PER_FRAME: u32 = 1000;
    let timescale = (fps * f64::from(TICKS_PER_FRAME)).round() as u32;
    let config = mp4::Mp4Config {
        major_brand: "isom".parse()?,
        minor_version: 512,
        compatible_brands: ["isom", "iso2", "avc1", "mp41"].iter().map(|b| b.parse()).collect::<Result<_, _>>()?,
        timescale,
    };
    let mut writer = mp4::Mp4Writer::write_start(Cursor::new(Vec::new()), &config)?;
    writer.add_track(&mp4::TrackConfig {
        track_type: mp4::TrackType::Video,
        timescale,
        language: "und".into(),
        media_conf: mp4::MediaConfig::AvcConfig(mp4::AvcConfig {
            width: width as u16,
            height: height as u16,
            seq_param_set,
            pic_param_set,
        }),
    })?;
    for (i, frame) in frames.iter().enumerate() {
        let sample = mp4::Mp4Sample {
            start_time: i as u64 * u64::from(TICKS_PER_FRAME),
            duration: TICKS_PER_FRAME,
            rendering_offset: 0,
            is_sync: frame.key,
            bytes: mp4::Bytes::copy_from_slice(&frame.data),
        };
        writer.write_sample(1, &sample)?;
    }
    writer.write_end()?;
    Ok(writer.into_writer().into_inner())
}

#[cfg(test)]
mod tests {
    use super::*;
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// An avcC record with one SPS (High profile, level 4.0) and one PPS.
    fn avcc() -> Vec<u8> {
        let sps = [0x67, 0x64, 0x00, 0x28, 0xac, 0xd9, 0x40, 0x50];
        let pps = [0x68, 0xeb, 0xe3, 0xcb];
        let mut v = vec![1, 0x64, 0x00, 0x28, 0xff, 0xe1];
        v.extend_from_slice(&(sps.len() as u16).to_be_bytes());
        v.extend_from_slice(&sps);
        v.push(1);
        v.extend_from_slice(&(pps.len() as u16).to_be_bytes());
        v.extend_from_slice(&pps);
        v
    }

    fn frame(key: bool, i: u8) -> EncodedFrame {
        // One length-prefixed NAL unit: an IDR slice (type 5) or a non-IDR one (type 1).
        EncodedFrame { key, data: vec![0, 0, 0, 3, if key { 0x65 } else { 0x41 }, i, 0x80] }
    }

    #[test]
    fn the_parameter_sets_come_out_of_the_description() {
        let (sps, pps) = parameter_sets(&avcc()).unwrap();
        assert_eq!((sps[0], sps.len(), pps[0], pps.len()), (0x67, 8, 0x68, 4));
        for bad in [&[][..], &[0, 1, 2, 3, 4, 5, 6][..], &avcc()[..10], &avcc()[..avcc().len() - 1]] {
            assert!(matches!(parameter_sets(bad), Err(VideoError::BadDescription(_))), "{bad:?}");
        }
    }

    #[test]
    fn avcc_record_is_the_inverse_of_parameter_sets() {
        let (sps, pps) = parameter_sets(&avcc()).unwrap();
        assert_eq!(avcc_record(&sps, &pps).unwrap(), avcc());
        assert!(avcc_record(&sps[..3], &pps).is_err());
    }

    #[test]
    fn the_mp4_holds_every_frame_at_the_session_rate() {
        let frames: Vec<_> = (0..45).map(|i| frame(i % 30 == 0, i as u8)).collect();
        let bytes = h264_mp4(&avcc(), 640, 360, 29.97, &frames).unwrap();
        let size = bytes.len() as u64;
        let mut reader = mp4::Mp4Reader::read_header(Cursor::new(bytes), size).unwrap();
        let track = reader.tracks().get(&1).unwrap();
        assert_eq!(track.media_type().unwrap(), mp4::MediaType::H264);
        assert_eq!((track.width(), track.height()), (640, 360));
        assert_eq!(track.sample_count(), 45);
        assert_eq!(track.timescale(), 29_970);
        assert_eq!(track.sequence_parameter_set().unwrap()[0], 0x67);
        let durations = (1..=45).map(|i| reader.read_sample(1, i).unwrap().unwrap()).collect::<Vec<_>>();
        assert!(durations.iter().all(|s| s.duration == 1000));
        let keys: Vec<u32> = (1..=45u32).filter(|&i| durations[i as usize - 1].is_sync).collect();
        assert_eq!(keys, [1, 31]);
        assert_eq!(&durations[44].bytes[..], &frames[44].data[..]);
    }

    #[test]
    fn bad_input_gets_a_reason() {
        let ok = [frame(true, 0)];
        assert!(matches!(h264_mp4(&avcc(), 641, 360, 30.0, &ok), Err(VideoError::BadSize { .. })));
        assert!(matches!(h264_mp4(&avcc(), 640, 360, f64::NAN, &ok), Err(VideoError::BadFrameRate(_))));
        assert!(matches!(h264_mp4(&avcc(), 640, 360, 30.0, &[]), Err(VideoError::NoFrames)));
        assert!(matches!(h264_mp4(&avcc(), 640, 360, 30.0, &[frame(false, 0)]), Err(VideoError::NoLeadingKeyFrame)));
        let empty = [frame(true, 0), EncodedFrame { key: false, data: vec![] }];
        assert!(matches!(h264_mp4(&avcc(), 640, 360, 30.0, &empty), Err(VideoError::EmptyFrame { index: 1 })));
        assert!(matches!(h264_mp4(&[1, 2], 640, 360, 30.0, &ok), Err(VideoError::BadDescription(_))));
    }
}
