//! Acclaim Motion Capture (AMC) parser: per-frame DOF values for an [`AsfSkeleton`].
//!
//! An AMC file has a header (`#` comments, `:FULLY-SPECIFIED`, `:DEGREES`/`:RADIANS`), then
//! frames: a line with the frame number, then one line per bone that has DOFs —
//! `name v1 v2 …` in the bone's `dof` order (the root's in its `order`). Angles are in the
//! AMC's unit (else the ASF's); root translation is in ASF length units.
//!
//! Values are stored per frame in the skeleton's channel layout ([`ChannelLayout`]): the
//! root's channels first, then each bone's DOFs in ASF bone order. Parsing works on a
//! string and never panics; errors name the file and line.

use crate::asf::{AngleUnit, AsfSkeleton};
use crate::error::{ParseError, ParseErrorKind, parse_number};

/// Where each bone's values sit in a frame's channel vector.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelLayout {
    /// Number of root channels (they come first).
    pub root_channels: usize,
    /// Offset of each ASF bone's first value (bones without DOFs get an empty range).
    pub bone_offsets: Vec<usize>,
    /// Total channels per frame.
    pub channels_per_frame: usize,
}

impl ChannelLayout {
    /// The layout of a skeleton's frames.
    pub fn of(skeleton: &AsfSkeleton) -> Self {
        let root_channels = skeleton.root.order.len();
        let mut offset = root_channels;
        let bone_offsets = skeleton
            .bones
            .iter()
            .map(|b| {
                let at = offset;
                offset += b.dofs.len();
                at
            })
            .collect();
        Self { root_channels, bone_offsets, channels_per_frame: offset }
    }
}

/// A parsed AMC motion.
#[derive(Clone, Debug, PartialEq)]
pub struct AmcMotion {
    /// The frame number of the first frame as written in the file (CMU starts at 1).
    pub first_frame_number: i64,
    /// Unit of the rotation values.
    pub angle_unit: AngleUnit,
    /// Channels per frame ([`ChannelLayout::channels_per_frame`]).
    pub channels_per_frame: usize,
    /// `frames × channels_per_frame` values: angles in `angle_unit`, translations in ASF
    /// length units.
    pub values: Vec<f32>,
}

impl AmcMotion {
    /// Number of frames.
    pub fn frame_count(&self) -> usize {
        self.values.len().checked_div(self.channels_per_frame).unwrap_or(0)
    }

    /// The values of frame `i` (empty past the end).
    pub fn frame(&self, i: usize) -> &[f32] {
        let n = self.channels_per_frame;
        self.values.get(i * n..(i + 1) * n).unwrap_or(&[])
    }

    /// Parses AMC text for `skeleton`. `file` names the input in errors.
    ///
    /// Every bone with DOFs must appear exactly once per frame with exactly its number of
    /// values; frame numbers must count up by one. A file cut off mid-frame is an error.
    pub fn parse(text: &str, file: &str, skeleton: &AsfSkeleton) -> Result<Self, ParseError> {
        let layout = ChannelLayout::of(skeleton);
        let n = layout.channels_per_frame;
        // Bones that must appear in each frame: (name, offset, count); index 0 is the root.
        let mut expected: Vec<(&str, usize, usize)> = vec![("root", 0, layout.root_channels)];
        for (b, bone) in skeleton.bones.iter().enumerate() {
            if !bone.dofs.is_empty() {
                expected.push((bone.name.as_str(), layout.bone_offsets[b], bone.dofs.len()));
            }
        }

        let mut angle_unit = skeleton.units.angle;
        let mut values: Vec<f32> = Vec::with_capacity(text.len() / 8);
        let mut first_frame_number = None;
        let mut current_frame: Option<(i64, usize)> = None; // (number, line)
        let mut seen = vec![false; expected.len()];

        let check_complete = |frame: i64, line: usize, seen: &[bool]| -> Result<(), ParseError> {
            match seen.iter().position(|s| !s) {
                Some(missing) => Err(ParseError::at(
                    file,
                    line,
                    ParseErrorKind::MissingBoneInFrame { frame, bone: expected[missing].0.to_owned() },
                )),
                None => Ok(()),
            }
        };

        for (index, raw) in text.trim_start_matches('\u{feff}').lines().enumerate() {
            let line_no = index + 1;
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            if let Some(keyword) = line.strip_prefix(':') {
                if current_frame.is_some() {
                    return Err(ParseError::at(
                        file,
                        line_no,
                        ParseErrorKind::Expected { expected: "a bone line or a frame number", found: line.to_owned() },
                    ));
                }
                match keyword.trim().to_ascii_uppercase().as_str() {
                    "DEGREES" => angle_unit = AngleUnit::Degrees,
                    "RADIANS" => angle_unit = AngleUnit::Radians,
                    _ => {}
                }
                continue;
            }
            let mut tokens = line.split_whitespace();
            let Some(first) = tokens.next() else { continue };

            if first.as_bytes()[0].is_ascii_digit() || first.starts_with('-') {
                // A frame number line.
                let number: i64 = match (first.parse(), tokens.next()) {
                    (Ok(v), None) => v,
                    _ => {
                        return Err(ParseError::at(
                            file,
                            line_no,
                            ParseErrorKind::Expected { expected: "a frame number", found: line.to_owned() },
                        ));
                    }
                };
                if let Some((previous, previous_line)) = current_frame {
                    check_complete(previous, previous_line, &seen)?;
                    if number != previous + 1 {
                        return Err(ParseError::at(
                            file,
                            line_no,
                            ParseErrorKind::FrameOutOfSequence { previous, found: number },
                        ));
                    }
                } else {
                    first_frame_number = Some(number);
                }
                current_frame = Some((number, line_no));
                seen.iter_mut().for_each(|s| *s = false);
                values.resize(values.len() + n, 0.0);
                continue;
            }

            let Some((frame, _)) = current_frame else {
                return Err(ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::Expected { expected: "a frame number before bone values", found: line.to_owned() },
                ));
            };
            let Some(slot) = expected.iter().position(|(name, _, _)| *name == first) else {
                let known = skeleton.bones.iter().any(|b| b.name == first);
                let kind = if known {
                    ParseErrorKind::WrongValueCount { bone: first.to_owned(), expected: 0, found: tokens.count() }
                } else {
                    ParseErrorKind::UnknownBone(first.to_owned())
                };
                return Err(ParseError::at(file, line_no, kind));
            };
            if seen[slot] {
                return Err(ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::RepeatedBoneInFrame { frame, bone: first.to_owned() },
                ));
            }
            seen[slot] = true;
            let (_, offset, count) = expected[slot];
            let base = values.len() - n + offset;
            let mut found = 0;
            for token in tokens {
                if found < count {
                    values[base + found] = parse_number(file, line_no, token)? as f32;
                }
                found += 1;
            }
            if found != count {
                return Err(ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::WrongValueCount { bone: first.to_owned(), expected: count, found },
                ));
            }
        }

        let Some((last, last_line)) = current_frame else {
            return Err(ParseError::in_file(file, ParseErrorKind::UnexpectedEnd { expected: "at least one frame" }));
        };
        check_complete(last, last_line, &seen)?;
        Ok(Self { first_frame_number: first_frame_number.unwrap_or(1), angle_unit, channels_per_frame: n, values })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ASF: &str = "\
:units
  length 0.45
  angle deg
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     name a
     direction 0 1 0
     length 1
     axis 0 0 0 XYZ
     dof rx rz
  end
  begin
     name b
     direction 0 1 0
     length 1
     axis 0 0 0 XYZ
  end
:hierarchy
  begin
    root a
    a b
  end
";

    #[test]
    fn parses_frames_in_layout_order() {
        let asf = AsfSkeleton::parse(ASF, "t.asf").unwrap();
        let amc = ":FULLY-SPECIFIED\n:DEGREES\n1\na 10 20\nroot 1 2 3 4 5 6\n2\nroot 0 0 0 0 0 0\na -1 -2\n";
        let motion = AmcMotion::parse(amc, "t.amc", &asf).unwrap();
        assert_eq!(motion.frame_count(), 2);
        assert_eq!(motion.frame(0), &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 10.0, 20.0]);
        assert_eq!(motion.frame(1)[6..], [-1.0, -2.0]);
        assert!(motion.frame(2).is_empty());
    }

    #[test]
    fn truncated_last_frame_is_an_error() {
        let asf = AsfSkeleton::parse(ASF, "t.asf").unwrap();
        let err = AmcMotion::parse("1\nroot 0 0 0 0 0 0\na 1 2\n2\nroot 0 0 0 0 0 0\n", "t.amc", &asf).unwrap_err();
        assert_eq!(err.location.line, Some(4));
        assert!(matches!(err.kind, ParseErrorKind::MissingBoneInFrame { frame: 2, .. }), "{err}");
    }
}
