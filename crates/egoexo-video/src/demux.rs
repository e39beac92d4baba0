//! Reading an H.264 track out of an MP4 file (ISO/IEC 14496-12 and -15): the `mp4` crate
//! parses the boxes; this module turns the track's sample tables (`stsz`, `stsc`, `stco`/
//! `co64`, `stts`, `ctts`, `stss`) into one entry per sample, so a sample is a slice of the
//! file's bytes — no copy of the file, no reader kept alive (the browser's worker decodes
//! asynchronously, sample by sample).
//!
//! Times are the track's ticks; presentation time = decode time + the `ctts` offset. Edit
//! lists are not applied: the first presented frame is time 0 (see [`H264Track::presentation_ns`]).

use std::io::Cursor;

use mp4::WriteBox;

use crate::VideoError;

/// At most this many samples in a track (10 hours at 30 fps): a bound on what a hostile file
/// can make the reader allocate.
pub const MAX_SAMPLES: usize = 1_080_000;

/// One encoded frame's place and times in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct VideoSample {
    /// Byte offset of the sample in the file.
    pub offset: u64,
    /// Its size, bytes.
    pub size: u32,
    /// Decode time, track ticks.
    pub decode_ticks: i64,
    /// Presentation (composition) time, track ticks.
    pub presentation_ticks: i64,
    /// A key frame (sync sample): decoding can start here.
    pub key: bool,
}

/// The first H.264 video track of an MP4 file.
#[derive(Clone, Debug, PartialEq)]
pub struct H264Track {
    /// Coded picture size, pixels.
    pub width: u32,
    pub height: u32,
    /// Track ticks per second.
    pub timescale: u32,
    /// The `AVCDecoderConfigurationRecord` (the `avcC` box's body; WebCodecs' `description`).
    pub avcc: Vec<u8>,
    /// RFC 6381 codec string, `avc1.PPCCLL` (WebCodecs' `codec`).
    pub codec: String,
    /// Bytes of each NAL unit's length prefix in the samples (1, 2 or 4).
    pub nal_length_size: u8,
    /// Sequence and picture parameter sets (for Annex B streams).
    pub sps: Vec<Vec<u8>>,
    pub pps: Vec<Vec<u8>>,
    /// Every sample, in decode order.
    pub samples: Vec<VideoSample>,
}

impl H264Track {
    /// Reads the first H.264 (`avc1`) track of the MP4 file `mp4`.
    pub fn read(mp4: &[u8]) -> Result<Self, VideoError> {
        let reader = mp4::Mp4Reader::read_header(Cursor::new(mp4), mp4.len() as u64)
            .map_err(|e| VideoError::NotMp4(e.to_string()))?;
        if !reader.moofs.is_empty() {
            return Err(VideoError::Fragmented);
        }
        let mut ids: Vec<u32> = reader.tracks().keys().copied().collect();
        ids.sort_unstable();
        let track =
            ids.iter().map(|id| &reader.tracks()[id]).find(|t| t.trak.mdia.minf.stbl.stsd.avc1.is_some()).ok_or_else(
                || VideoError::NoH264Track {
                    found: if ids.is_empty() {
                        "none".into()
                    } else {
                        ids.iter()
                            .map(|id| {
                                let t = &reader.tracks()[id];
                                t.box_type().map(|b| format!("{id}: {b}")).unwrap_or_else(|_| format!("{id}: unknown"))
                            })
                            .collect::<Vec<_>>()
                            .join(", ")
                    },
                },
            )?;
        let stbl = &track.trak.mdia.minf.stbl;
        let avc1 = stbl.stsd.avc1.as_ref().expect("found above");
        let (width, height) = (u32::from(avc1.width), u32::from(avc1.height));
        if !(1..=8192).contains(&width) || !(1..=8192).contains(&height) {
            return Err(VideoError::BadDimensions { width, height });
        }
        let mut avcc = Vec::new();
        avc1.avcc.write_box(&mut avcc).map_err(|e| VideoError::BadDescription(e.to_string()))?;
        let avcc = avcc.split_off(8); // the box's size and type
        let c = &avc1.avcc;
        let codec = format!(
            "avc1.{:02x}{:02x}{:02x}",
            c.avc_profile_indication, c.profile_compatibility, c.avc_level_indication
        );
        let nal_length_size = (c.length_size_minus_one & 3) + 1;
        if nal_length_size == 3 {
            return Err(VideoError::BadDescription("a NAL unit length size of 3 bytes is not allowed".into()));
        }
        let sps: Vec<Vec<u8>> = c.sequence_parameter_sets.iter().map(|n| n.bytes.clone()).collect();
        let pps: Vec<Vec<u8>> = c.picture_parameter_sets.iter().map(|n| n.bytes.clone()).collect();
        if sps.is_empty() || pps.is_empty() {
            return Err(VideoError::BadDescription("expected at least one SPS and one PPS".into()));
        }
        let timescale = track.trak.mdia.mdhd.timescale;
        if timescale == 0 {
            return Err(VideoError::BadSampleTables("the track's timescale is 0".into()));
        }
        let samples = sample_table(track, mp4.len())?;
        Ok(Self { width, height, timescale, avcc, codec, nal_length_size, sps, pps, samples })
    }

    /// Sample `index`'s bytes (length-prefixed NAL units), a slice of `mp4`.
    pub fn sample_bytes<'a>(&self, mp4: &'a [u8], index: usize) -> Result<&'a [u8], VideoError> {
        let s = self.samples.get(index).ok_or_else(|| {
            VideoError::BadSampleTables(format!("sample {index} asked for, the track has {}", self.samples.len()))
        })?;
        let end = s.offset + u64::from(s.size);
        usize::try_from(s.offset)
            .ok()
            .zip(usize::try_from(end).ok())
            .and_then(|(a, b)| mp4.get(a..b))
            .ok_or(VideoError::SampleOutsideFile { index, offset: s.offset, end, file_len: mp4.len() })
    }

    /// The earliest presentation time of any sample, ticks.
    pub fn first_presentation_ticks(&self) -> i64 {
        self.samples.iter().map(|s| s.presentation_ticks).min().unwrap_or(0)
    }

    /// Sample `index`'s presentation time after the first presented frame, nanoseconds.
    pub fn presentation_ns(&self, index: usize) -> i64 {
        let ticks = i128::from(self.samples[index].presentation_ticks - self.first_presentation_ticks());
        (ticks * 1_000_000_000 / i128::from(self.timescale)) as i64
    }

    /// Sample indices in presentation order (the order decoders output frames).
    pub fn presentation_order(&self) -> Vec<usize> {
        let mut order: Vec<usize> = (0..self.samples.len()).collect();
        order.sort_by_key(|&i| (self.samples[i].presentation_ticks, i));
        order
    }

    /// Sample `index` of `mp4` as an Annex B access unit (start codes instead of length
    /// prefixes), led by the parameter sets when it is a key frame — what native decoders
    /// such as OpenH264 read.
    pub fn annex_b(&self, mp4: &[u8], index: usize) -> Result<Vec<u8>, VideoError> {
        let bytes = self.sample_bytes(mp4, index)?;
        let mut out = Vec::with_capacity(bytes.len() + 64);
        if self.samples[index].key {
            for set in self.sps.iter().chain(&self.pps) {
                out.extend_from_slice(&[0, 0, 0, 1]);
                out.extend_from_slice(set);
            }
        }
        let n = usize::from(self.nal_length_size);
        let bad = VideoError::BadNalUnits { index, length_size: self.nal_length_size };
        let mut at = 0;
        while at < bytes.len() {
            let prefix =
                bytes.get(at..at + n).ok_or(VideoError::BadNalUnits { index, length_size: self.nal_length_size })?;
            let len = prefix.iter().fold(0usize, |acc, &b| (acc << 8) | usize::from(b));
            let unit = bytes.get(at + n..at + n + len).filter(|u| !u.is_empty());
            let Some(unit) = unit else { return Err(bad) };
            out.extend_from_slice(&[0, 0, 0, 1]);
            out.extend_from_slice(unit);
            at += n + len;
        }
        Ok(out)
    }
}

/// One entry per sample from `track`'s sample tables, checked against the file's length.
fn sample_table(track: &mp4::Mp4Track, file_len: usize) -> Result<Vec<VideoSample>, VideoError> {
    let stbl = &track.trak.mdia.minf.stbl;
    let bad = VideoError::BadSampleTables;
    let count = stbl.stsz.sample_count as usize;
    if count == 0 {
        return Err(bad("the track has no samples".into()));
    }
    if count > MAX_SAMPLES {
        return Err(bad(format!("{count} samples; at most {MAX_SAMPLES} are read")));
    }
    let sizes: Vec<u32> = if stbl.stsz.sample_size != 0 {
        vec![stbl.stsz.sample_size; count]
    } else if stbl.stsz.sample_sizes.len() == count {
        stbl.stsz.sample_sizes.clone()
    } else {
        return Err(bad(format!("stsz lists {} sizes for {count} samples", stbl.stsz.sample_sizes.len())));
    };
    let chunk_offsets: Vec<u64> = match (&stbl.stco, &stbl.co64) {
        (Some(stco), _) => stco.entries.iter().map(|&o| u64::from(o)).collect(),
        (None, Some(co64)) => co64.entries.clone(),
        (None, None) => return Err(bad("no chunk offsets (stco or co64)".into())),
    };
    // Offsets: walk the chunks, each holding `samples_per_chunk` of the stsc entry it falls in.
    let mut offsets = Vec::with_capacity(count);
    let entries = &stbl.stsc.entries;
    if entries.is_empty() || entries[0].first_chunk != 1 {
        return Err(bad("stsc must start at chunk 1".into()));
    }
    'chunks: for (e, entry) in entries.iter().enumerate() {
        let last_chunk = match entries.get(e + 1) {
            Some(next) if next.first_chunk > entry.first_chunk => next.first_chunk - 1,
            Some(_) => return Err(bad("stsc's chunk numbers do not increase".into())),
            None => chunk_offsets.len() as u32,
        };
        for chunk in entry.first_chunk..=last_chunk {
            let mut at = *chunk_offsets
                .get(chunk as usize - 1)
                .ok_or_else(|| bad(format!("stsc names chunk {chunk}, there are {}", chunk_offsets.len())))?;
            for _ in 0..entry.samples_per_chunk {
                if offsets.len() == count {
                    break 'chunks;
                }
                offsets.push(at);
                at += u64::from(sizes[offsets.len() - 1]);
            }
        }
    }
    if offsets.len() != count {
        return Err(bad(format!("the chunks hold {} samples, stsz says {count}", offsets.len())));
    }
    // Decode times from stts, composition offsets from ctts.
    let mut decode = Vec::with_capacity(count);
    let mut t: i64 = 0;
    for entry in &stbl.stts.entries {
        for _ in 0..entry.sample_count {
            if decode.len() == count {
                break;
            }
            decode.push(t);
            t += i64::from(entry.sample_delta);
        }
    }
    if decode.len() != count {
        return Err(bad(format!("stts times {} samples of {count}", decode.len())));
    }
    let mut composition = vec![0i64; count];
    if let Some(ctts) = &stbl.ctts {
        let mut i = 0usize;
        for entry in &ctts.entries {
            for _ in 0..entry.sample_count {
                if i == count {
                    break;
                }
                composition[i] = i64::from(entry.sample_offset);
                i += 1;
            }
        }
    }
    let mut key = vec![stbl.stss.is_none(); count];
    if let Some(stss) = &stbl.stss {
        for &n in &stss.entries {
            match key.get_mut((n as usize).wrapping_sub(1)) {
                Some(k) => *k = true,
                None => return Err(bad(format!("stss names sample {n} of {count}"))),
            }
        }
    }
    let samples: Vec<VideoSample> = (0..count)
        .map(|i| VideoSample {
            offset: offsets[i],
            size: sizes[i],
            decode_ticks: decode[i],
            presentation_ticks: decode[i] + composition[i],
            key: key[i],
        })
        .collect();
    for (index, s) in samples.iter().enumerate() {
        let end = s.offset + u64::from(s.size);
        if end > file_len as u64 {
            return Err(VideoError::SampleOutsideFile { index, offset: s.offset, end, file_len });
        }
    }
    Ok(samples)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mux::{EncodedFrame, h264_mp4};
    #[cfg(target_arch = "wasm32")]
    use wasm_bindgen_test::wasm_bindgen_test as test;

    /// An avcC record with one SPS (High profile, level 4.0) and one PPS.
    fn avcc() -> Vec<u8> {
        crate::avcc_record(&[0x67, 0x64, 0x00, 0x28, 0xac, 0xd9, 0x40, 0x50], &[0x68, 0xeb, 0xe3, 0xcb]).unwrap()
    }

    /// Frame `i`: two length-prefixed NAL units of different lengths (so offsets matter).
    fn frame(i: usize) -> EncodedFrame {
        let key = i.is_multiple_of(10);
        let mut data = vec![0, 0, 0, 2, 0x09, 0xf0]; // access unit delimiter
        let body: Vec<u8> = (0..(3 + i % 7)).map(|j| (i * 31 + j) as u8).collect();
        data.extend_from_slice(&(body.len() as u32 + 1).to_be_bytes());
        data.push(if key { 0x65 } else { 0x41 });
        data.extend_from_slice(&body);
        EncodedFrame { key, data }
    }

    #[test]
    fn a_written_video_reads_back_sample_for_sample() {
        let frames: Vec<_> = (0..37).map(frame).collect();
        let mp4 = h264_mp4(&avcc(), 320, 240, 30.0, &frames).unwrap();
        let track = H264Track::read(&mp4).unwrap();
        assert_eq!((track.width, track.height, track.timescale), (320, 240, 30_000));
        assert_eq!(track.codec, "avc1.640028");
        assert_eq!(track.avcc, avcc());
        assert_eq!(track.nal_length_size, 4);
        assert_eq!(track.samples.len(), 37);
        for (i, f) in frames.iter().enumerate() {
            assert_eq!(track.sample_bytes(&mp4, i).unwrap(), &f.data[..], "sample {i}");
            assert_eq!(track.samples[i].key, f.key);
            assert_eq!(track.presentation_ns(i), (i as i64 * 1_000_000_000) / 30);
        }
        assert_eq!(track.presentation_order(), (0..37).collect::<Vec<_>>());
    }

    #[test]
    fn annex_b_replaces_length_prefixes_and_leads_key_frames_with_parameter_sets() {
        let frames: Vec<_> = (0..12).map(frame).collect();
        let mp4 = h264_mp4(&avcc(), 320, 240, 30.0, &frames).unwrap();
        let track = H264Track::read(&mp4).unwrap();
        let key = track.annex_b(&mp4, 10).unwrap();
        assert!(key.starts_with(&[0, 0, 0, 1, 0x67]));
        let starts = key.windows(4).filter(|w| *w == [0, 0, 0, 1]).count();
        assert_eq!(starts, 4, "SPS, PPS, delimiter, slice");
        let delta = track.annex_b(&mp4, 11).unwrap();
        assert_eq!(&delta[..6], &[0, 0, 0, 1, 0x09, 0xf0]);
        assert_eq!(delta[10], 0x41);
    }

    #[test]
    fn bad_files_get_a_reason() {
        assert!(matches!(H264Track::read(b"not an mp4 at all"), Err(VideoError::NotMp4(_))));
        let frames: Vec<_> = (0..5).map(frame).collect();
        let mp4 = h264_mp4(&avcc(), 320, 240, 30.0, &frames).unwrap();
        let track = H264Track::read(&mp4).unwrap();
        let short = &mp4[..track.samples[4].offset as usize + 2];
        assert!(matches!(track.sample_bytes(short, 4), Err(VideoError::SampleOutsideFile { index: 4, .. })));
        // A sample whose length prefix runs past its end.
        let mut broken = mp4.clone();
        let at = track.samples[2].offset as usize;
        broken[at..at + 4].copy_from_slice(&1000u32.to_be_bytes());
        assert!(matches!(track.annex_b(&broken, 2), Err(VideoError::BadNalUnits { index: 2, length_size: 4 })));
    }
}
