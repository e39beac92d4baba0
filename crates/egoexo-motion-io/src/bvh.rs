//! BVH (Biovision Hierarchy) motion files: a general reader, forward kinematics over what it
//! read, and a writer.
//!
//! The reader accepts any hierarchy and any channel layout: each joint may have any subset of
//! the six channels (`Xposition Yposition Zposition Xrotation Yrotation Zrotation`, in any
//! order, keywords matched case-insensitively), `End Site`s anywhere, `{` on the keyword's
//! line or the next, CRLF line ends and a UTF-8 byte-order mark. It works on in-memory text,
//! never panics, reports every problem with its 1-based line number, and caps what untrusted
//! input can make it allocate ([`MAX_JOINTS`], [`MAX_DEPTH`], [`MAX_FRAMES`], [`MAX_VALUES`]).
//!
//! # Conventions (those of Biovision, Blender and most tools)
//! - **Rotation channels** are in degrees. A joint's local rotation is the product of its
//!   rotation channels' elementary rotations *in the order listed*: `Zrotation Xrotation
//!   Yrotation` means `R = Rz(z) · Rx(x) · Ry(y)` (intrinsic Z, then X, then Y), acting on column
//!   vectors expressed in the joint's frame and giving them in the parent's frame. That is
//!   [`EulerOrder::ZXY`] in the project's one Euler convention (`egoexo_core::euler`).
//! - **Position channels** give the joint's origin in its parent's frame and *replace* the
//!   matching `OFFSET` component (Blender's reading, and bvhio's). Writers usually give such
//!   joints (the root) `OFFSET 0 0 0`, so that reading and "offset + channels" agree.
//! - A joint's world transform is `T_world_joint = T_world_parent · Translate(t) · R`, with `t`
//!   the offset (or position channels) and `R` the local rotation.
//! - **Units and axes** are whatever the file uses (often centimetres or inches, usually Y up):
//!   this module neither scales nor rotates; callers that know the source do.

use std::fmt::Write as _;

use egoexo_core::euler::{Axis, EulerOrder};
use egoexo_core::glam::{DQuat, DVec3};
use thiserror::Error;

/// Most joints a hierarchy may declare.
pub const MAX_JOINTS: usize = 1024;
/// Deepest nesting of joints (and end sites) accepted.
pub const MAX_DEPTH: usize = 256;
/// Most frames a file may declare.
pub const MAX_FRAMES: usize = 2_000_000;
/// Most channel values (frames × channels) a file may declare.
pub const MAX_VALUES: usize = 100_000_000;
/// Most channels one joint may declare (each of the six at most once).
pub const MAX_CHANNELS_PER_JOINT: usize = 6;

/// One animated degree of freedom of a joint.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

impl Channel {
    /// All six, positions first.
    pub const ALL: [Channel; 6] = [
        Channel::Xposition,
        Channel::Yposition,
        Channel::Zposition,
        Channel::Xrotation,
        Channel::Yrotation,
        Channel::Zrotation,
    ];

    /// The keyword as BVH files spell it (`Xposition`, …).
    pub fn name(self) -> &'static str {
        match self {
            Channel::Xposition => "Xposition",
            Channel::Yposition => "Yposition",
            Channel::Zposition => "Zposition",
            Channel::Xrotation => "Xrotation",
            Channel::Yrotation => "Yrotation",
            Channel::Zrotation => "Zrotation",
        }
    }

    /// Parses a channel keyword, ignoring ASCII case.
    pub fn parse(keyword: &str) -> Option<Channel> {
        Channel::ALL.into_iter().find(|c| c.name().eq_ignore_ascii_case(keyword))
    }

    /// The axis it moves along or about.
    pub fn axis(self) -> Axis {
        match self {
            Channel::Xposition | Channel::Xrotation => Axis::X,
            Channel::Yposition | Channel::Yrotation => Axis::Y,
            Channel::Zposition | Channel::Zrotation => Axis::Z,
        }
    }

    /// A rotation channel (degrees), as opposed to a position channel (file units).
    pub fn is_rotation(self) -> bool {
        matches!(self, Channel::Xrotation | Channel::Yrotation | Channel::Zrotation)
    }

    /// The rotation channel about `axis`.
    pub fn rotation(axis: Axis) -> Channel {
        match axis {
            Axis::X => Channel::Xrotation,
            Axis::Y => Channel::Yrotation,
            Axis::Z => Channel::Zrotation,
        }
    }

    /// The three rotation channels of `order`, as a file lists them (product order,
    /// outermost first: `ZXY` is `Zrotation Xrotation Yrotation`).
    pub fn rotations(order: EulerOrder) -> [Channel; 3] {
        order.axes().map(Channel::rotation)
    }
}

impl std::fmt::Display for Channel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// One joint of a hierarchy.
#[derive(Clone, Debug, PartialEq)]
pub struct BvhJoint {
    /// The name after `ROOT`/`JOINT` (the rest of that line; may contain spaces).
    pub name: String,
    /// Index of the parent joint; `None` for the root.
    pub parent: Option<usize>,
    /// `OFFSET`: the joint's origin in its parent's frame (file units).
    pub offset: DVec3,
    /// The joint's channels in file order.
    pub channels: Vec<Channel>,
    /// `End Site` offset from this joint (file units), if the joint has one.
    pub end_site: Option<DVec3>,
}

/// A joint's transform in its parent's frame (or the world's, for the root) for one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BvhPose {
    /// Origin (file units).
    pub translation: DVec3,
    /// Orientation.
    pub rotation: DQuat,
}

/// A parsed (or to-be-written) BVH file: the hierarchy, the frame time and the channel values.
///
/// Joints are in file (depth-first) order: every parent precedes its children and each
/// subtree is contiguous. A frame holds every joint's channel values, joint by joint.
#[derive(Clone, Debug, PartialEq)]
pub struct Bvh {
    joints: Vec<BvhJoint>,
    /// Column of each joint's first channel in a frame.
    first_channel: Vec<usize>,
    num_channels: usize,
    frame_time_s: f64,
    /// Frame-major channel values.
    values: Vec<f64>,
}

/// What went wrong reading (or assembling) a BVH file. Lines are 1-based.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum BvhError {
    #[error("not UTF-8 text (invalid byte at offset {offset})")]
    NotUtf8 { offset: usize },
    #[error("line {line}: expected {expected}, found `{found}`")]
    Unexpected { line: usize, expected: &'static str, found: String },
    #[error("unexpected end of file after line {line}: expected {expected}")]
    UnexpectedEof { line: usize, expected: &'static str },
    #[error("line {line}: {field} must be {expected}, got `{found}`")]
    InvalidValue { line: usize, field: &'static str, expected: &'static str, found: String },
    #[error("line {line}: joint `{joint}`: {problem}")]
    Joint { line: usize, joint: String, problem: String },
    #[error("line {line}: {what} exceeds the limit of {limit}")]
    TooLarge { line: usize, what: &'static str, limit: usize },
    #[error("line {line}: frame {frame} has {found} values, expected {expected} (one per channel)")]
    FrameLength { line: usize, frame: usize, expected: usize, found: usize },
    #[error(
        "line {line}: frame {frame}, value {column} (`{joint}` {channel}): expected a finite number, got `{found}`"
    )]
    FrameValue { line: usize, frame: usize, column: usize, joint: String, channel: Channel, found: String },
    #[error("the file ends after {found} of the {declared} frames that `Frames:` declares")]
    MissingFrames { declared: usize, found: usize },
    #[error("line {line}: more frames than the {declared} that `Frames:` declares")]
    ExtraFrames { line: usize, declared: usize },
    #[error("invalid BVH data: {0}")]
    Invalid(String),
}

impl Bvh {
    /// Assembles a file from parts, checking what a writer relies on: one root first, joints
    /// in depth-first order, at most one of each channel per joint, finite offsets, a positive
    /// finite frame time, and `values` a whole number of frames of finite numbers.
    pub fn new(joints: Vec<BvhJoint>, frame_time_s: f64, values: Vec<f64>) -> Result<Bvh, BvhError> {
        let invalid = |m: String| Err(BvhError::Invalid(m));
        if joints.is_empty() {
            return invalid("no joints".into());
        }
        if joints.len() > MAX_JOINTS {
            return invalid(format!("{} joints; at most {MAX_JOINTS}", joints.len()));
        }
        if !(frame_time_s.is_finite() && frame_time_s > 0.0) {
            return invalid(format!("frame time must be positive and finite, got {frame_time_s}"));
        }
        let mut stack: Vec<usize> = Vec::new();
        let mut first_channel = Vec::with_capacity(joints.len());
        let mut num_channels = 0;
        for (j, joint) in joints.iter().enumerate() {
            match (j, joint.parent) {
                (0, None) => {}
                (0, Some(_)) => return invalid(format!("first joint `{}` must be the root", joint.name)),
                (_, None) => return invalid(format!("joint `{}` is a second root", joint.name)),
                (_, Some(p)) => {
                    while stack.last().is_some_and(|&top| top != p) {
                        stack.pop();
                    }
                    if stack.is_empty() {
                        return invalid(format!(
                            "joint {j} (`{}`) names parent {p}, which is not an open ancestor (joints must be in depth-first order)",
                            joint.name
                        ));
                    }
                }
            }
            stack.push(j);
            if stack.len() > MAX_DEPTH {
                return invalid(format!("hierarchy deeper than {MAX_DEPTH}"));
            }
            if joint.name.trim().is_empty() || joint.name.contains(['\n', '\r', '{', '}']) {
                return invalid(format!("joint {j} has an empty or unwritable name {:?}", joint.name));
            }
            if !joint.offset.is_finite() || joint.end_site.is_some_and(|e| !e.is_finite()) {
                return invalid(format!("joint `{}` has a non-finite offset", joint.name));
            }
            if let Some(problem) = channel_list_problem(&joint.channels) {
                return invalid(format!("joint `{}`: {problem}", joint.name));
            }
            first_channel.push(num_channels);
            num_channels += joint.channels.len();
        }
        if num_channels == 0 {
            if !values.is_empty() {
                return invalid("values given but no joint has channels".into());
            }
        } else if !values.len().is_multiple_of(num_channels) {
            return invalid(format!("{} values is not a whole number of {num_channels}-channel frames", values.len()));
        }
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return invalid(format!("value {i} is not finite"));
        }
        if num_channels > 0 && values.len() / num_channels > MAX_FRAMES {
            return invalid(format!("more than {MAX_FRAMES} frames"));
        }
        Ok(Bvh { joints, first_channel, num_channels, frame_time_s, values })
    }

    /// Parses BVH bytes (UTF-8, optionally with a byte-order mark).
    pub fn parse_bytes(bytes: &[u8]) -> Result<Bvh, BvhError> {
        let text = std::str::from_utf8(bytes).map_err(|e| BvhError::NotUtf8 { offset: e.valid_up_to() })?;
        Bvh::parse(text)
    }

    /// Parses BVH text.
    pub fn parse(text: &str) -> Result<Bvh, BvhError> {
        Parser::new(text.strip_prefix('\u{feff}').unwrap_or(text)).parse()
    }

    /// The parts [`Bvh::new`] takes: joints, frame time, frame-major values.
    pub fn into_parts(self) -> (Vec<BvhJoint>, f64, Vec<f64>) {
        (self.joints, self.frame_time_s, self.values)
    }

    /// The joints in file order.
    pub fn joints(&self) -> &[BvhJoint] {
        &self.joints
    }

    /// Index of the first joint named `name` (exact match).
    pub fn joint_index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Seconds between frames (`Frame Time:`).
    pub fn frame_time_s(&self) -> f64 {
        self.frame_time_s
    }

    /// Channels per frame (all joints).
    pub fn num_channels(&self) -> usize {
        self.num_channels
    }

    /// Number of frames.
    pub fn num_frames(&self) -> usize {
        self.values.len().checked_div(self.num_channels).unwrap_or(0)
    }

    /// Column of joint `joint`'s first channel within a frame.
    pub fn first_channel(&self, joint: usize) -> Option<usize> {
        self.first_channel.get(joint).copied()
    }

    /// All channel values of frame `frame`, in column order.
    pub fn frame(&self, frame: usize) -> Option<&[f64]> {
        let start = frame.checked_mul(self.num_channels)?;
        self.values.get(start..start + self.num_channels).filter(|_| frame < self.num_frames())
    }

    /// Joint `joint`'s channel values in frame `frame` (in the joint's channel order).
    pub fn joint_values(&self, joint: usize, frame: usize) -> Option<&[f64]> {
        let first = *self.first_channel.get(joint)?;
        self.frame(frame)?.get(first..first + self.joints[joint].channels.len())
    }

    /// Joint `joint`'s transform relative to its parent in frame `frame` (see the module's
    /// conventions); `None` when either index is out of range.
    pub fn local_pose(&self, joint: usize, frame: usize) -> Option<BvhPose> {
        let j = self.joints.get(joint)?;
        let values = self.joint_values(joint, frame)?;
        let mut translation = j.offset;
        let mut rotation = DQuat::IDENTITY;
        for (&channel, &value) in j.channels.iter().zip(values) {
            if channel.is_rotation() {
                rotation *= channel.axis().rotation_f64(value.to_radians());
            } else {
                translation[channel.axis().index()] = value;
            }
        }
        Some(BvhPose { translation, rotation })
    }

    /// World transforms of every joint in frame `frame` (forward kinematics); `None` when the
    /// frame is out of range.
    pub fn world_poses(&self, frame: usize) -> Option<Vec<BvhPose>> {
        if frame >= self.num_frames() {
            return None;
        }
        let mut world: Vec<BvhPose> = Vec::with_capacity(self.joints.len());
        for (j, joint) in self.joints.iter().enumerate() {
            let local = self.local_pose(j, frame)?;
            let pose = match joint.parent {
                None => local,
                Some(p) => {
                    let parent = world.get(p)?;
                    BvhPose {
                        translation: parent.translation + parent.rotation * local.translation,
                        rotation: (parent.rotation * local.rotation).normalize(),
                    }
                }
            };
            world.push(pose);
        }
        Some(world)
    }

    /// The file as BVH text: tab-indented hierarchy, numbers with `decimals` digits after the
    /// point, one line per frame, `\n` line ends.
    pub fn to_bvh_string(&self, decimals: usize) -> String {
        let decimals = decimals.min(17);
        let mut out = String::with_capacity(self.joints.len() * 120 + self.values.len() * (decimals + 6));
        let num = |v: f64| -> String {
            let s = format!("{v:.decimals$}");
            // Avoid "-0.000": some readers choke on a signed zero.
            if s.trim_start_matches('-').chars().all(|c| c == '0' || c == '.') {
                s.trim_start_matches('-').to_string()
            } else {
                s
            }
        };
        let vec3 = |v: DVec3| format!("{} {} {}", num(v.x), num(v.y), num(v.z));
        out.push_str("HIERARCHY\n");
        // Close joints whose subtree ended, depth-first (the order `new` checked).
        let mut open: Vec<usize> = Vec::new();
        let close = |out: &mut String, open: &mut Vec<usize>, joints: &[BvhJoint]| {
            if let Some(j) = open.pop() {
                let indent = "\t".repeat(open.len());
                if let Some(end) = joints[j].end_site {
                    let _ = write!(
                        out,
                        "{indent}\tEnd Site\n{indent}\t{{\n{indent}\t\tOFFSET {}\n{indent}\t}}\n",
                        vec3(end)
                    );
                }
                let _ = writeln!(out, "{indent}}}");
            }
        };
        for (j, joint) in self.joints.iter().enumerate() {
            while open.last().is_some_and(|&top| Some(top) != joint.parent) {
                close(&mut out, &mut open, &self.joints);
            }
            let indent = "\t".repeat(open.len());
            let keyword = if joint.parent.is_none() { "ROOT" } else { "JOINT" };
            let _ = write!(
                out,
                "{indent}{keyword} {}\n{indent}{{\n{indent}\tOFFSET {}\n",
                joint.name.trim(),
                vec3(joint.offset)
            );
            let _ = write!(out, "{indent}\tCHANNELS {}", joint.channels.len());
            for c in &joint.channels {
                let _ = write!(out, " {c}");
            }
            out.push('\n');
            open.push(j);
        }
        while !open.is_empty() {
            close(&mut out, &mut open, &self.joints);
        }
        let _ = write!(out, "MOTION\nFrames: {}\nFrame Time: {}\n", self.num_frames(), self.frame_time_s);
        if self.num_channels > 0 {
            for frame in self.values.chunks_exact(self.num_channels) {
                let line: Vec<String> = frame.iter().map(|&v| num(v)).collect();
                out.push_str(&line.join(" "));
                out.push('\n');
            }
        }
        out
    }
}

fn channel_list_problem(channels: &[Channel]) -> Option<String> {
    if channels.len() > MAX_CHANNELS_PER_JOINT {
        return Some(format!("{} channels; at most {MAX_CHANNELS_PER_JOINT}", channels.len()));
    }
    for (i, c) in channels.iter().enumerate() {
        if channels[..i].contains(c) {
            return Some(format!("channel {c} appears twice"));
        }
    }
    None
}

/// A token with its 1-based line.
#[derive(Clone, Copy, Debug)]
struct Token<'a> {
    line: usize,
    text: &'a str,
}

/// Reads the hierarchy token by token (across lines), then the motion data line by line.
struct Parser<'a> {
    lines: std::iter::Enumerate<std::str::Lines<'a>>,
    /// Tokens left on the current line, reversed (next token last).
    pending: Vec<&'a str>,
    line: usize,
}

impl<'a> Parser<'a> {
    fn new(text: &'a str) -> Self {
        Parser { lines: text.lines().enumerate(), pending: Vec::new(), line: 0 }
    }

    fn next_token(&mut self) -> Option<Token<'a>> {
        loop {
            if let Some(text) = self.pending.pop() {
                return Some(Token { line: self.line, text });
            }
            let (i, line) = self.lines.next()?;
            self.line = i + 1;
            self.pending = line.split_whitespace().rev().collect();
        }
    }

    fn expect_token(&mut self, expected: &'static str) -> Result<Token<'a>, BvhError> {
        self.next_token().ok_or(BvhError::UnexpectedEof { line: self.line, expected })
    }

    /// The next token, which must be `keyword` (ASCII case ignored).
    fn expect_keyword(&mut self, keyword: &'static str) -> Result<Token<'a>, BvhError> {
        let t = self.expect_token(keyword)?;
        if t.text.eq_ignore_ascii_case(keyword) {
            Ok(t)
        } else {
            Err(BvhError::Unexpected { line: t.line, expected: keyword, found: t.text.to_string() })
        }
    }

    fn expect_number(&mut self, field: &'static str) -> Result<f64, BvhError> {
        let t = self.expect_token(field)?;
        parse_finite(t.text).ok_or_else(|| BvhError::InvalidValue {
            line: t.line,
            field,
            expected: "a finite number",
            found: t.text.to_string(),
        })
    }

    fn expect_count(&mut self, field: &'static str, limit: usize) -> Result<usize, BvhError> {
        let t = self.expect_token(field)?;
        let n: usize = t.text.parse().map_err(|_| BvhError::InvalidValue {
            line: t.line,
            field,
            expected: "a non-negative integer",
            found: t.text.to_string(),
        })?;
        if n > limit {
            return Err(BvhError::TooLarge { line: t.line, what: field, limit });
        }
        Ok(n)
    }

    /// A joint name: the rest of the keyword's line, minus a trailing `{` (left for the
    /// caller to read as the opening brace).
    fn joint_name(&mut self, keyword: Token<'a>) -> Result<String, BvhError> {
        let mut words: Vec<&str> = Vec::new();
        while let Some(&w) = self.pending.last() {
            if w == "{" {
                break;
            }
            words.push(w);
            self.pending.pop();
        }
        if words.is_empty() {
            let found = self.pending.last().copied().unwrap_or("end of line").to_string();
            return Err(BvhError::Unexpected { line: keyword.line, expected: "a joint name", found });
        }
        Ok(words.join(" "))
    }

    fn parse(mut self) -> Result<Bvh, BvhError> {
        self.expect_keyword("HIERARCHY")?;
        let root = self.expect_keyword("ROOT")?;
        let joints = self.parse_hierarchy(root)?;

        let t = self.expect_token("MOTION")?;
        if t.text.eq_ignore_ascii_case("ROOT") {
            return Err(BvhError::Unexpected {
                line: t.line,
                expected: "MOTION (files with several ROOT hierarchies are not supported)",
                found: t.text.to_string(),
            });
        }
        if !t.text.eq_ignore_ascii_case("MOTION") {
            return Err(BvhError::Unexpected { line: t.line, expected: "MOTION", found: t.text.to_string() });
        }
        // `Frames: N`, also written `Frames : N`.
        let t = self.expect_token("Frames:")?;
        if t.text.eq_ignore_ascii_case("Frames") {
            self.expect_keyword(":")?;
        } else if !t.text.eq_ignore_ascii_case("Frames:") {
            return Err(BvhError::Unexpected { line: t.line, expected: "Frames:", found: t.text.to_string() });
        }
        let frames_line = self.line;
        let num_frames = self.expect_count("Frames", MAX_FRAMES)?;
        // `Frame Time: t`.
        self.expect_keyword("Frame")?;
        let t = self.expect_token("Time:")?;
        if t.text.eq_ignore_ascii_case("Time") {
            self.expect_keyword(":")?;
        } else if !t.text.eq_ignore_ascii_case("Time:") {
            return Err(BvhError::Unexpected { line: t.line, expected: "Time:", found: t.text.to_string() });
        }
        let time = self.expect_token("a frame time")?;
        let frame_time_s = parse_finite(time.text).filter(|&t| t > 0.0).ok_or_else(|| BvhError::InvalidValue {
            line: time.line,
            field: "Frame Time",
            expected: "a positive number of seconds",
            found: time.text.to_string(),
        })?;
        if let Some(extra) = self.pending.pop() {
            return Err(BvhError::Unexpected {
                line: self.line,
                expected: "end of line after the frame time",
                found: extra.into(),
            });
        }

        let first_channel: Vec<usize> = joints
            .iter()
            .scan(0, |n, j| {
                let first = *n;
                *n += j.channels.len();
                Some(first)
            })
            .collect();
        let num_channels: usize = joints.iter().map(|j| j.channels.len()).sum();
        if num_channels == 0 && num_frames > 0 {
            return Err(BvhError::InvalidValue {
                line: frames_line,
                field: "Frames",
                expected: "0 for a hierarchy without channels",
                found: num_frames.to_string(),
            });
        }
        if num_frames.saturating_mul(num_channels) > MAX_VALUES {
            return Err(BvhError::TooLarge { line: frames_line, what: "Frames × channels", limit: MAX_VALUES });
        }
        // Column → (joint, channel), for error messages.
        let column_owner = |column: usize| -> (String, Channel) {
            let j = first_channel.partition_point(|&f| f <= column).saturating_sub(1);
            let joint = &joints[j];
            (joint.name.clone(), joint.channels[column - first_channel[j]])
        };

        // Reserve for what the input can actually hold, not what it claims.
        let mut values = Vec::with_capacity((num_frames * num_channels).min(1 << 20));
        let mut frame = 0;
        for (i, line) in self.lines.by_ref() {
            let line_no = i + 1;
            if line.trim().is_empty() {
                continue;
            }
            if frame == num_frames {
                return Err(BvhError::ExtraFrames { line: line_no, declared: num_frames });
            }
            let start = values.len();
            for (column, text) in line.split_whitespace().enumerate() {
                if column >= num_channels {
                    let found = line.split_whitespace().count();
                    return Err(BvhError::FrameLength { line: line_no, frame, expected: num_channels, found });
                }
                let Some(v) = parse_finite(text) else {
                    let (joint, channel) = column_owner(column);
                    return Err(BvhError::FrameValue {
                        line: line_no,
                        frame,
                        column,
                        joint,
                        channel,
                        found: text.into(),
                    });
                };
                values.push(v);
            }
            if values.len() - start != num_channels {
                let found = values.len() - start;
                return Err(BvhError::FrameLength { line: line_no, frame, expected: num_channels, found });
            }
            frame += 1;
        }
        if frame < num_frames {
            return Err(BvhError::MissingFrames { declared: num_frames, found: frame });
        }
        Ok(Bvh { joints, first_channel, num_channels, frame_time_s, values })
    }

    /// From just after `ROOT` to the root's closing brace.
    fn parse_hierarchy(&mut self, root: Token<'a>) -> Result<Vec<BvhJoint>, BvhError> {
        struct Open {
            joint: usize,
            line: usize,
            has_offset: bool,
            has_channels: bool,
        }
        let mut joints: Vec<BvhJoint> = Vec::new();
        let mut open: Vec<Open> = Vec::new();
        // Declares a joint at `keyword` and reads its `{`.
        let begin_joint = |p: &mut Self, keyword: Token<'a>, open: &mut Vec<Open>, joints: &mut Vec<BvhJoint>| {
            let name = p.joint_name(keyword)?;
            if joints.len() == MAX_JOINTS {
                return Err(BvhError::TooLarge { line: keyword.line, what: "the number of joints", limit: MAX_JOINTS });
            }
            if open.len() == MAX_DEPTH {
                return Err(BvhError::TooLarge { line: keyword.line, what: "the hierarchy's depth", limit: MAX_DEPTH });
            }
            p.expect_keyword("{")?;
            joints.push(BvhJoint {
                name,
                parent: open.last().map(|o| o.joint),
                offset: DVec3::ZERO,
                channels: Vec::new(),
                end_site: None,
            });
            open.push(Open { joint: joints.len() - 1, line: keyword.line, has_offset: false, has_channels: false });
            Ok::<(), BvhError>(())
        };
        begin_joint(self, root, &mut open, &mut joints)?;

        while let Some(top) = open.last_mut() {
            let t = self.expect_token("OFFSET, CHANNELS, JOINT, End Site or }")?;
            let joint = &mut joints[top.joint];
            let joint_error =
                |line: usize, problem: String| BvhError::Joint { line, joint: joint.name.clone(), problem };
            match t.text {
                s if s.eq_ignore_ascii_case("OFFSET") => {
                    if top.has_offset {
                        return Err(joint_error(t.line, "a second OFFSET".into()));
                    }
                    let offset = self.read_vec3("OFFSET")?;
                    joints[top.joint].offset = offset;
                    top.has_offset = true;
                }
                s if s.eq_ignore_ascii_case("CHANNELS") => {
                    if top.has_channels {
                        return Err(joint_error(t.line, "a second CHANNELS".into()));
                    }
                    let n = self.expect_count("CHANNELS count", MAX_CHANNELS_PER_JOINT)?;
                    let mut channels = Vec::with_capacity(n);
                    for _ in 0..n {
                        let c = self.expect_token("a channel name")?;
                        let channel = Channel::parse(c.text).ok_or_else(|| BvhError::Unexpected {
                            line: c.line,
                            expected: "a channel (Xposition, Yposition, Zposition, Xrotation, Yrotation or Zrotation)",
                            found: c.text.to_string(),
                        })?;
                        if channels.contains(&channel) {
                            return Err(BvhError::Joint {
                                line: c.line,
                                joint: joints[top.joint].name.clone(),
                                problem: format!("channel {channel} appears twice"),
                            });
                        }
                        channels.push(channel);
                    }
                    joints[top.joint].channels = channels;
                    top.has_channels = true;
                }
                s if s.eq_ignore_ascii_case("JOINT") => {
                    if !top.has_offset {
                        return Err(joint_error(t.line, "a child JOINT before the joint's OFFSET".into()));
                    }
                    begin_joint(self, t, &mut open, &mut joints)?;
                }
                s if s.eq_ignore_ascii_case("End") => {
                    self.expect_keyword("Site")?;
                    if joint.end_site.is_some() {
                        return Err(joint_error(t.line, "a second End Site".into()));
                    }
                    if open.len() == MAX_DEPTH {
                        return Err(BvhError::TooLarge {
                            line: t.line,
                            what: "the hierarchy's depth",
                            limit: MAX_DEPTH,
                        });
                    }
                    self.expect_keyword("{")?;
                    self.expect_keyword("OFFSET")?;
                    let end = self.read_vec3("End Site OFFSET")?;
                    self.expect_keyword("}")?;
                    joints[open.last().map_or(0, |o| o.joint)].end_site = Some(end);
                }
                "}" => {
                    if !top.has_offset {
                        return Err(BvhError::Joint {
                            line: top.line,
                            joint: joint.name.clone(),
                            problem: "no OFFSET before its closing `}`".into(),
                        });
                    }
                    open.pop();
                }
                other => {
                    return Err(BvhError::Unexpected {
                        line: t.line,
                        expected: "OFFSET, CHANNELS, JOINT, End Site or }",
                        found: other.to_string(),
                    });
                }
            }
        }
        Ok(joints)
    }

    fn read_vec3(&mut self, field: &'static str) -> Result<DVec3, BvhError> {
        Ok(DVec3::new(self.expect_number(field)?, self.expect_number(field)?, self.expect_number(field)?))
    }
}

/// A finite `f64`, or `None` (also for `nan`, `inf`, `infinity` which Rust's parser accepts).
fn parse_finite(text: &str) -> Option<f64> {
    text.parse::<f64>().ok().filter(|v| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_JOINTS: &str = "HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Chest
\t{
\t\tOFFSET 0 10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 5 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 2 3 0 0 0 0 0 0
1 2 3 90 0 0 0 90 0
";

    fn close(a: DVec3, b: DVec3) -> bool {
        a.distance(b) < 1e-9
    }

    #[test]
    fn parses_a_small_file_and_runs_forward_kinematics() {
        let bvh = Bvh::parse(TWO_JOINTS).unwrap();
        assert_eq!(bvh.joints().len(), 2);
        assert_eq!(bvh.num_channels(), 9);
        assert_eq!(bvh.num_frames(), 2);
        assert_eq!(bvh.joints()[1].parent, Some(0));
        assert_eq!(bvh.joints()[1].end_site, Some(DVec3::new(0.0, 5.0, 0.0)));
        assert!((bvh.frame_time_s() - 0.0333333).abs() < 1e-12);
        let rest = bvh.world_poses(0).unwrap();
        assert!(close(rest[0].translation, DVec3::new(1.0, 2.0, 3.0)));
        assert!(close(rest[1].translation, DVec3::new(1.0, 12.0, 3.0)));
        // Frame 1: the root turns 90° about Z, so the chest's +Y offset points along −X.
        let posed = bvh.world_poses(1).unwrap();
        assert!(close(posed[1].translation, DVec3::new(-9.0, 2.0, 3.0)), "{:?}", posed[1].translation);
        assert!(bvh.world_poses(2).is_none());
    }

    #[test]
    fn rotation_channels_compose_in_file_order() {
        let text = TWO_JOINTS.replace("1 2 3 90 0 0 0 90 0", "0 0 0 30 40 50 0 0 0");
        let bvh = Bvh::parse(&text).unwrap();
        let r = bvh.local_pose(0, 1).unwrap().rotation;
        let expected = EulerOrder::ZXY.to_quat_f64([30f64, 40.0, 50.0].map(f64::to_radians));
        assert!(r.abs_diff_eq(expected, 1e-12));
        let rz = DQuat::from_rotation_z(30f64.to_radians());
        let rx = DQuat::from_rotation_x(40f64.to_radians());
        let ry = DQuat::from_rotation_y(50f64.to_radians());
        assert!(r.abs_diff_eq(rz * rx * ry, 1e-12));
        assert!(!r.abs_diff_eq(ry * rx * rz, 1e-3));
    }

    #[test]
    fn writer_output_parses_back_identically() {
        let bvh = Bvh::parse(TWO_JOINTS).unwrap();
        let text = bvh.to_bvh_string(6);
        let again = Bvh::parse(&text).unwrap();
        assert_eq!(again.joints(), bvh.joints());
        assert_eq!(again.frame(1), bvh.frame(1));
        assert_eq!(again.frame_time_s(), bvh.frame_time_s());
    }

    #[test]
    fn accepts_common_layout_variants() {
        let text = "\u{feff}hierarchy\r\nROOT Left Hip {\r\n OFFSET 1 2 3\r\n CHANNELS 3 yposition Xposition Zrotation\r\n \
                    End Site {\r\n OFFSET 0 1 0 }\r\n}\r\nMOTION\r\nFrames : 1\r\nFrame Time : 0.01\r\n\r\n5 6 90\r\n\r\n";
        let bvh = Bvh::parse(text).unwrap();
        assert_eq!(bvh.joints()[0].name, "Left Hip");
        let pose = bvh.local_pose(0, 0).unwrap();
        // Position channels replace the OFFSET's components; Z keeps the offset's 3.
        assert!(close(pose.translation, DVec3::new(6.0, 5.0, 3.0)));
    }

    #[test]
    fn reads_the_number_forms_real_files_use() {
        let text = TWO_JOINTS
            .replace("Frame Time: 0.0333333", "Frame Time: .0083333")
            .replace("1 2 3 90 0 0 0 90 0", "1. +2 3e0 90 -0 .5 -.5 9.0E1 0");
        let bvh = Bvh::parse(&text).unwrap();
        assert!((bvh.frame_time_s() - 0.0083333).abs() < 1e-12);
        assert_eq!(bvh.frame(1).unwrap(), [1.0, 2.0, 3.0, 90.0, 0.0, 0.5, -0.5, 90.0, 0.0]);
    }

    #[test]
    fn hierarchy_without_channels_and_zero_frames_is_fine() {
        let text = "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\n}\nMOTION\nFrames: 0\nFrame Time: 0.1\n";
        let bvh = Bvh::parse(text).unwrap();
        assert_eq!(bvh.num_frames(), 0);
        assert!(bvh.world_poses(0).is_none());
    }

    /// Malformed inputs: each gives its specific error (with the right line), none panics.
    #[test]
    fn malformed_inputs_give_line_numbered_errors() {
        let cases: Vec<(String, &str)> = vec![
            (String::new(), "unexpected end of file after line 0: expected HIERARCHY"),
            ("HIERARCHY\nJOINT a".into(), "line 2: expected ROOT, found `JOINT`"),
            (
                TWO_JOINTS.replace("OFFSET 0 10 0", "OFFSET 0 ten 0"),
                "line 8: OFFSET must be a finite number, got `ten`",
            ),
            (TWO_JOINTS.replace("OFFSET 0 10 0", "OFFSET 0 inf 0"), "line 8: OFFSET must be a finite number"),
            (TWO_JOINTS.replace("CHANNELS 3 Zrotation", "CHANNELS 3 Wrotation"), "line 9: expected a channel"),
            (
                TWO_JOINTS.replace("CHANNELS 3 Zrotation Xrotation", "CHANNELS 3 Xrotation Xrotation"),
                "channel Xrotation appears twice",
            ),
            (
                TWO_JOINTS.replace("CHANNELS 3 Zrotation", "CHANNELS 7 Zrotation"),
                "line 9: CHANNELS count exceeds the limit of 6",
            ),
            (
                TWO_JOINTS.replace("CHANNELS 3 Zrotation", "CHANNELS -3 Zrotation"),
                "CHANNELS count must be a non-negative integer",
            ),
            (TWO_JOINTS.replace("\t\tOFFSET 0 10 0\n", ""), "line 6: joint `Chest`: no OFFSET before its closing `}`"),
            (
                TWO_JOINTS.replace("OFFSET 0 10 0", "OFFSET 0 10 0\nOFFSET 1 1 1"),
                "line 9: joint `Chest`: a second OFFSET",
            ),
            (TWO_JOINTS.replace("JOINT Chest", "JOINT"), "line 6: expected a joint name, found `end of line`"),
            (TWO_JOINTS.replace("Frames: 2", "Frames: 3"), "the file ends after 2 of the 3 frames"),
            (TWO_JOINTS.replace("Frames: 2", "Frames: 1"), "line 20: more frames than the 1"),
            (
                TWO_JOINTS.replace("Frames: 2", "Frames: two"),
                "line 17: Frames must be a non-negative integer, got `two`",
            ),
            (TWO_JOINTS.replace("Frames: 2", "Frames: 99999999999"), "line 17: Frames exceeds the limit"),
            (
                TWO_JOINTS.replace("Frame Time: 0.0333333", "Frame Time: 0"),
                "line 18: Frame Time must be a positive number",
            ),
            (TWO_JOINTS.replace("Frame Time: 0.0333333", "Frame Time: NaN"), "Frame Time must be a positive number"),
            (
                TWO_JOINTS.replace("1 2 3 90 0 0 0 90 0", "1 2 3 90 0 0 0 90"),
                "line 20: frame 1 has 8 values, expected 9",
            ),
            (
                TWO_JOINTS.replace("1 2 3 90 0 0 0 90 0", "1 2 3 90 0 0 0 90 0 1"),
                "line 20: frame 1 has 10 values, expected 9",
            ),
            (
                TWO_JOINTS.replace("1 2 3 90 0 0 0 90 0", "1 2 3 90 0 0 0 nan 0"),
                "line 20: frame 1, value 7 (`Chest` Xrotation): expected a finite number, got `nan`",
            ),
            (TWO_JOINTS.replace("MOTION", "ROOT b"), "files with several ROOT hierarchies are not supported"),
            (TWO_JOINTS.replace("MOTION\n", ""), "line 16: expected MOTION, found `Frames:`"),
            (
                TWO_JOINTS.replace("}\nMOTION", "MOTION"),
                "expected OFFSET, CHANNELS, JOINT, End Site or }, found `MOTION`",
            ),
            (TWO_JOINTS.replace("\t\t\tOFFSET 0 5 0\n", ""), "line 12: expected OFFSET, found `}`"),
            (TWO_JOINTS[..120].to_string(), "unexpected end of file"),
        ];
        for (text, expected) in cases {
            let err = Bvh::parse(&text).expect_err(expected).to_string();
            assert!(err.contains(expected), "expected `{expected}`, got `{err}`");
        }
        assert!(matches!(Bvh::parse_bytes(b"HIERARCHY\n\xff"), Err(BvhError::NotUtf8 { offset: 10 })));
    }

    #[test]
    fn caps_joint_count_and_depth() {
        let mut deep = String::from("HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\n");
        for i in 0..(MAX_DEPTH + 5) {
            deep.push_str(&format!("JOINT j{i}\n{{\nOFFSET 0 1 0\n"));
        }
        let err = Bvh::parse(&deep).unwrap_err();
        assert!(matches!(err, BvhError::TooLarge { what: "the hierarchy's depth", .. }), "{err}");

        let mut wide = String::from("HIERARCHY\nROOT r\n{\nOFFSET 0 0 0\n");
        for i in 0..(MAX_JOINTS + 5) {
            wide.push_str(&format!("JOINT j{i}\n{{\nOFFSET 0 1 0\n}}\n"));
        }
        let err = Bvh::parse(&wide).unwrap_err();
        assert!(matches!(err, BvhError::TooLarge { what: "the number of joints", .. }), "{err}");
    }

    #[test]
    fn truncated_prefixes_never_panic() {
        for end in 0..TWO_JOINTS.len() {
            if TWO_JOINTS.is_char_boundary(end) {
                let _ = Bvh::parse(&TWO_JOINTS[..end]);
            }
        }
    }

    proptest::proptest! {
        /// Random edits of a valid file (tokens dropped, replaced or duplicated, bytes
        /// inserted) give a file or an error, never a panic.
        #[test]
        fn mutated_files_never_panic(
            edits in proptest::collection::vec((0usize..200, 0usize..4, "[ -~\n\t]{0,6}"), 1..6)
        ) {
            let mut tokens: Vec<String> = TWO_JOINTS.split_inclusive(char::is_whitespace).map(str::to_string).collect();
            for (at, kind, text) in edits {
                let at = at % (tokens.len() + 1);
                match kind {
                    0 if at < tokens.len() => { tokens.remove(at); }
                    1 if at < tokens.len() => tokens[at] = format!("{text} "),
                    2 if at < tokens.len() => { let t = tokens[at].clone(); tokens.insert(at, t); }
                    _ => tokens.insert(at, text),
                }
            }
            let text = tokens.concat();
            if let Ok(bvh) = Bvh::parse(&text) {
                for frame in 0..bvh.num_frames() {
                    proptest::prop_assert!(bvh.world_poses(frame).is_some());
                }
                let again = Bvh::parse(&bvh.to_bvh_string(9));
                proptest::prop_assert!(again.is_ok(), "{:?}", again);
            }
        }
    }

    #[test]
    fn new_rejects_what_cannot_be_written() {
        let joint = |name: &str, parent| BvhJoint {
            name: name.into(),
            parent,
            offset: DVec3::ZERO,
            channels: vec![Channel::Xrotation],
            end_site: None,
        };
        assert!(Bvh::new(vec![joint("a", None), joint("b", Some(0))], 0.1, vec![0.0, 1.0]).is_ok());
        assert!(Bvh::new(vec![joint("a", None), joint("b", None)], 0.1, vec![]).is_err());
        assert!(Bvh::new(vec![joint("a", None), joint("b", Some(1))], 0.1, vec![]).is_err());
        assert!(Bvh::new(vec![joint("a", None)], 0.0, vec![]).is_err());
        assert!(Bvh::new(vec![joint("a", None)], 0.1, vec![f64::NAN]).is_err());
        assert!(Bvh::new(vec![joint("a", None), joint("b", Some(0))], 0.1, vec![0.0]).is_err());
        assert!(Bvh::new(vec![joint("a {", None)], 0.1, vec![]).is_err());
    }
}
