//! Acclaim Skeleton File (ASF) parser, as written by the CMU motion capture database.
//!
//! An ASF describes the skeleton in its rest pose, in the *global* frame of the capture
//! (CMU: Y up, the subject faces +Z, the subject's left is +X):
//! - `:units` — `length` (file units per inch for CMU: 0.45), `mass`, `angle` (`deg`/`rad`);
//! - `:root` — `order` (the channels of the root's AMC line), `axis` (Euler order of the
//!   root orientation), `position`, `orientation`;
//! - `:bonedata` — per bone: unit `direction` (rest pose, global frame), `length` (file
//!   units), `axis X Y Z ORDER` (the bone's local frame as Euler angles relative to the
//!   global frame), `dof` (the order of the bone's AMC values) and `limits`;
//! - `:hierarchy` — `parent child child …` lines.
//!
//! Parsing works on a string (no I/O) and never panics; errors name the file and line.

use egoexo_core::euler::{Axis, EulerOrder};

use crate::error::{ParseError, ParseErrorKind, parse_number};

/// Unit of the angles in an ASF/AMC pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AngleUnit {
    Degrees,
    Radians,
}

impl AngleUnit {
    /// Factor that turns a value in this unit into radians.
    pub fn to_radians(self) -> f64 {
        match self {
            AngleUnit::Degrees => std::f64::consts::PI / 180.0,
            AngleUnit::Radians => 1.0,
        }
    }
}

/// The `:units` section.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AsfUnits {
    /// Mass multiplier (unused by kinematics).
    pub mass: f64,
    /// Length multiplier: file length units per inch (CMU: 0.45, so one unit is
    /// 1/0.45 inch = 0.056444 m).
    pub length: f64,
    /// Unit of every angle in the ASF and (unless the AMC overrides it) the AMC.
    pub angle: AngleUnit,
}

impl Default for AsfUnits {
    fn default() -> Self {
        Self { mass: 1.0, length: 1.0, angle: AngleUnit::Degrees }
    }
}

impl AsfUnits {
    /// Metres per file length unit: `(1 / length) × 0.0254` (CMU FAQ: 0.056444 m).
    pub fn metres_per_unit(&self) -> f64 {
        0.0254 / self.length
    }
}

/// The Euler order of an ASF `axis` token: ASF names the axes in the order they are applied,
/// first applied first (`XYZ`: X, then Y, then Z, i.e. `R = Rz · Ry · Rx`), which is
/// [`EulerOrder::ZYX`] in the project's convention (`egoexo_core::euler`).
fn parse_axis_order(token: &str) -> Option<EulerOrder> {
    EulerOrder::parse(token).and_then(|as_written| EulerOrder::from_applied_first(as_written.axes()))
}

/// One degree of freedom of a bone or the root (a channel of the AMC line).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dof {
    /// Translation along an axis (file length units).
    Translation(Axis),
    /// Rotation about an axis of the bone's local frame (angle unit).
    Rotation(Axis),
    /// Change of bone length (`l`, file length units).
    Length,
}

impl Dof {
    fn parse(token: &str) -> Option<Self> {
        Some(match token.to_ascii_lowercase().as_str() {
            "tx" => Dof::Translation(Axis::X),
            "ty" => Dof::Translation(Axis::Y),
            "tz" => Dof::Translation(Axis::Z),
            "rx" => Dof::Rotation(Axis::X),
            "ry" => Dof::Rotation(Axis::Y),
            "rz" => Dof::Rotation(Axis::Z),
            "l" => Dof::Length,
            _ => return None,
        })
    }
}

/// The `:root` section.
#[derive(Clone, Debug, PartialEq)]
pub struct AsfRoot {
    /// Channels of the root's AMC line, in order (CMU: `TX TY TZ RX RY RZ`).
    pub order: Vec<Dof>,
    /// Euler order of `orientation` and of the root rotation channels.
    pub axis: EulerOrder,
    /// Rest position, file length units.
    pub position: [f64; 3],
    /// Rest orientation (Euler angles in `axis` order), angle unit.
    pub orientation: [f64; 3],
}

impl Default for AsfRoot {
    fn default() -> Self {
        Self {
            order: vec![
                Dof::Translation(Axis::X),
                Dof::Translation(Axis::Y),
                Dof::Translation(Axis::Z),
                Dof::Rotation(Axis::X),
                Dof::Rotation(Axis::Y),
                Dof::Rotation(Axis::Z),
            ],
            axis: EulerOrder::ZYX,
            position: [0.0; 3],
            orientation: [0.0; 3],
        }
    }
}

/// One bone of `:bonedata`, with its parent from `:hierarchy`.
#[derive(Clone, Debug, PartialEq)]
pub struct AsfBone {
    /// `id` when given.
    pub id: Option<i64>,
    pub name: String,
    /// Unit direction from the bone's start to its end in the rest pose, global frame.
    pub direction: [f64; 3],
    /// Length, file length units.
    pub length: f64,
    /// Euler angles (angle unit) of the bone's local frame relative to the global frame.
    pub axis: [f64; 3],
    /// Order of `axis`.
    pub axis_order: EulerOrder,
    /// Degrees of freedom, in the order of the bone's AMC values.
    pub dofs: Vec<Dof>,
    /// Joint limits per DOF (angle or length units; may be infinite). Empty when not given.
    pub limits: Vec<(f64, f64)>,
    /// Index of the parent bone in [`AsfSkeleton::bones`], `None` for a child of the root.
    pub parent: Option<usize>,
}

/// A parsed ASF skeleton.
#[derive(Clone, Debug, PartialEq)]
pub struct AsfSkeleton {
    /// `:name`, when given.
    pub name: Option<String>,
    pub units: AsfUnits,
    pub root: AsfRoot,
    /// Bones in file order (the root is not a bone here).
    pub bones: Vec<AsfBone>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Section {
    None,
    Ignored,
    Units,
    Root,
    BoneData,
    Hierarchy,
}

/// Per-bone fields while a `begin … end` block is open.
#[derive(Default)]
struct BoneBuilder {
    begin_line: usize,
    id: Option<i64>,
    name: Option<String>,
    direction: Option<[f64; 3]>,
    length: Option<f64>,
    axis: Option<([f64; 3], EulerOrder)>,
    dofs: Vec<Dof>,
    limits: Vec<(f64, f64)>,
    /// Line of the `limits` keyword while its continuation lines are being read.
    limits_open: bool,
}

impl AsfSkeleton {
    /// Parses ASF text. `file` names the input in errors.
    pub fn parse(text: &str, file: &str) -> Result<Self, ParseError> {
        let mut name = None;
        let mut units = AsfUnits::default();
        let mut root = AsfRoot::default();
        let mut bones: Vec<AsfBone> = Vec::new();
        let mut seen_bonedata = false;
        let mut seen_hierarchy = false;
        let mut seen_root = false;
        let mut section = Section::None;
        let mut bone: Option<BoneBuilder> = None;
        let mut hierarchy_open = false;
        // (line, parent, children) from the hierarchy, resolved after every bone is known.
        let mut links: Vec<(usize, String, Vec<String>)> = Vec::new();

        for (index, raw) in text.trim_start_matches('\u{feff}').lines().enumerate() {
            let line_no = index + 1;
            let line = raw.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let mut tokens = line.split_whitespace();
            let Some(first) = tokens.next() else { continue };

            if let Some(keyword) = first.strip_prefix(':') {
                if let Some(open) = &bone {
                    return Err(ParseError::at(
                        file,
                        line_no,
                        ParseErrorKind::Expected {
                            expected: "`end` closing the bone opened on line before a new section",
                            found: format!("{first} (bone opened on line {})", open.begin_line),
                        },
                    ));
                }
                section = match keyword.to_ascii_lowercase().as_str() {
                    "units" => Section::Units,
                    "root" => {
                        seen_root = true;
                        Section::Root
                    }
                    "bonedata" => {
                        seen_bonedata = true;
                        Section::BoneData
                    }
                    "hierarchy" => {
                        seen_hierarchy = true;
                        Section::Hierarchy
                    }
                    "name" => {
                        name = tokens.next().map(str::to_owned);
                        Section::None
                    }
                    // :version, :documentation, :skin and anything else carry nothing the
                    // kinematics needs.
                    _ => Section::Ignored,
                };
                continue;
            }

            match section {
                Section::None => {
                    return Err(ParseError::at(
                        file,
                        line_no,
                        ParseErrorKind::Expected { expected: "a `:section` keyword", found: first.to_owned() },
                    ));
                }
                Section::Ignored => {}
                Section::Units => parse_units_line(file, line_no, first, tokens, &mut units)?,
                Section::Root => parse_root_line(file, line_no, first, tokens, &mut root)?,
                Section::BoneData => {
                    if let Some(done) = parse_bone_line(file, line_no, line, &mut bone)? {
                        if bones.iter().any(|b| b.name == done.name) {
                            return Err(ParseError::at(file, line_no, ParseErrorKind::DuplicateBone(done.name)));
                        }
                        bones.push(done);
                    }
                }
                Section::Hierarchy => {
                    let lower = first.to_ascii_lowercase();
                    if lower == "begin" {
                        hierarchy_open = true;
                    } else if lower == "end" {
                        hierarchy_open = false;
                    } else {
                        if !hierarchy_open {
                            return Err(ParseError::at(
                                file,
                                line_no,
                                ParseErrorKind::Expected { expected: "`begin`", found: first.to_owned() },
                            ));
                        }
                        let children: Vec<String> = tokens.map(str::to_owned).collect();
                        if children.is_empty() {
                            return Err(ParseError::at(
                                file,
                                line_no,
                                ParseErrorKind::Expected { expected: "`parent child …`", found: line.to_owned() },
                            ));
                        }
                        links.push((line_no, first.to_owned(), children));
                    }
                }
            }
        }

        if let Some(open) = bone {
            return Err(ParseError::at(
                file,
                open.begin_line,
                ParseErrorKind::UnexpectedEnd { expected: "`end` closing this bone" },
            ));
        }
        if hierarchy_open {
            return Err(ParseError::in_file(file, ParseErrorKind::UnexpectedEnd { expected: "`end` of :hierarchy" }));
        }
        if !seen_root {
            return Err(ParseError::in_file(file, ParseErrorKind::MissingSection(":root")));
        }
        if !seen_bonedata {
            return Err(ParseError::in_file(file, ParseErrorKind::MissingSection(":bonedata")));
        }
        if !seen_hierarchy {
            return Err(ParseError::in_file(file, ParseErrorKind::MissingSection(":hierarchy")));
        }

        resolve_hierarchy(file, &mut bones, &links)?;
        Ok(Self { name, units, root, bones })
    }

    /// Index of the bone called `name`.
    pub fn bone_index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }
}

fn expect_numbers<const N: usize>(
    file: &str,
    line: usize,
    mut tokens: std::str::SplitWhitespace<'_>,
    expected: &'static str,
) -> Result<[f64; N], ParseError> {
    let mut out = [0.0; N];
    for slot in &mut out {
        let token = tokens
            .next()
            .ok_or_else(|| ParseError::at(file, line, ParseErrorKind::Expected { expected, found: String::new() }))?;
        *slot = parse_number(file, line, token)?;
    }
    Ok(out)
}

fn parse_units_line(
    file: &str,
    line: usize,
    key: &str,
    mut tokens: std::str::SplitWhitespace<'_>,
    units: &mut AsfUnits,
) -> Result<(), ParseError> {
    let value = tokens.next().unwrap_or("");
    match key.to_ascii_lowercase().as_str() {
        "mass" => units.mass = parse_number(file, line, value)?,
        "length" => {
            let length = parse_number(file, line, value)?;
            if length <= 0.0 {
                return Err(ParseError::at(
                    file,
                    line,
                    ParseErrorKind::Expected { expected: "a positive length unit", found: value.to_owned() },
                ));
            }
            units.length = length;
        }
        "angle" => {
            units.angle = match value.to_ascii_lowercase().as_str() {
                "deg" | "degree" | "degrees" => AngleUnit::Degrees,
                "rad" | "radian" | "radians" => AngleUnit::Radians,
                _ => {
                    return Err(ParseError::at(
                        file,
                        line,
                        ParseErrorKind::Expected { expected: "`deg` or `rad`", found: value.to_owned() },
                    ));
                }
            }
        }
        // Other unit keys (e.g. `time`) do not affect kinematics.
        _ => {}
    }
    Ok(())
}

fn parse_root_line(
    file: &str,
    line: usize,
    key: &str,
    tokens: std::str::SplitWhitespace<'_>,
    root: &mut AsfRoot,
) -> Result<(), ParseError> {
    match key.to_ascii_lowercase().as_str() {
        "order" => {
            let mut order = Vec::new();
            for token in tokens {
                let dof = Dof::parse(token).filter(|d| *d != Dof::Length).ok_or_else(|| {
                    ParseError::at(
                        file,
                        line,
                        ParseErrorKind::Expected {
                            expected: "a root channel (TX TY TZ RX RY RZ)",
                            found: token.to_owned(),
                        },
                    )
                })?;
                if order.contains(&dof) {
                    return Err(ParseError::at(
                        file,
                        line,
                        ParseErrorKind::Invalid(format!("root channel `{token}` is listed twice")),
                    ));
                }
                order.push(dof);
            }
            root.order = order;
        }
        "axis" => {
            let mut tokens = tokens;
            let token = tokens.next().unwrap_or("");
            root.axis = parse_axis_order(token).ok_or_else(|| {
                ParseError::at(
                    file,
                    line,
                    ParseErrorKind::Expected { expected: "an Euler order such as XYZ", found: token.to_owned() },
                )
            })?;
        }
        "position" => root.position = expect_numbers(file, line, tokens, "three numbers")?,
        "orientation" => root.orientation = expect_numbers(file, line, tokens, "three numbers")?,
        other => {
            return Err(ParseError::at(
                file,
                line,
                ParseErrorKind::Expected { expected: "order, axis, position or orientation", found: other.to_owned() },
            ));
        }
    }
    Ok(())
}

/// Parses `(lo hi)` pairs from the text of a `limits` line or its continuation.
fn parse_limit_pairs(file: &str, line: usize, text: &str, limits: &mut Vec<(f64, f64)>) -> Result<(), ParseError> {
    let cleaned: String = text.chars().map(|c| if c == '(' || c == ')' { ' ' } else { c }).collect();
    let values: Vec<&str> = cleaned.split_whitespace().collect();
    if !values.len().is_multiple_of(2) {
        return Err(ParseError::at(
            file,
            line,
            ParseErrorKind::Expected { expected: "limits as `(min max)` pairs", found: text.trim().to_owned() },
        ));
    }
    for pair in values.chunks_exact(2) {
        let parse = |t: &str| -> Result<f64, ParseError> {
            match t.to_ascii_lowercase().as_str() {
                "inf" | "+inf" => Ok(f64::INFINITY),
                "-inf" => Ok(f64::NEG_INFINITY),
                _ => parse_number(file, line, t),
            }
        };
        limits.push((parse(pair[0])?, parse(pair[1])?));
    }
    Ok(())
}

/// Handles one line inside `:bonedata`; returns a finished bone at its `end`.
fn parse_bone_line(
    file: &str,
    line_no: usize,
    line: &str,
    open: &mut Option<BoneBuilder>,
) -> Result<Option<AsfBone>, ParseError> {
    let mut tokens = line.split_whitespace();
    let key = tokens.next().unwrap_or("").to_ascii_lowercase();
    let Some(bone) = open else {
        if key == "begin" {
            *open = Some(BoneBuilder { begin_line: line_no, ..Default::default() });
            return Ok(None);
        }
        return Err(ParseError::at(
            file,
            line_no,
            ParseErrorKind::Expected { expected: "`begin`", found: line.to_owned() },
        ));
    };

    if line.starts_with('(') {
        if !bone.limits_open {
            return Err(ParseError::at(
                file,
                line_no,
                ParseErrorKind::Expected { expected: "a bone field", found: line.to_owned() },
            ));
        }
        parse_limit_pairs(file, line_no, line, &mut bone.limits)?;
        return Ok(None);
    }
    bone.limits_open = false;

    match key.as_str() {
        "begin" => {
            return Err(ParseError::at(
                file,
                line_no,
                ParseErrorKind::Expected {
                    expected: "`end` before the next `begin`",
                    found: format!("begin (bone opened on line {})", bone.begin_line),
                },
            ));
        }
        "id" => {
            let token = tokens.next().unwrap_or("");
            bone.id = Some(token.parse().map_err(|_| {
                ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::Expected { expected: "an integer id", found: token.to_owned() },
                )
            })?);
        }
        "name" => {
            let token = tokens.next().ok_or_else(|| {
                ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::Expected { expected: "a bone name", found: String::new() },
                )
            })?;
            bone.name = Some(token.to_owned());
        }
        "direction" => bone.direction = Some(expect_numbers(file, line_no, tokens, "three numbers")?),
        "length" => {
            let [length] = expect_numbers(file, line_no, tokens, "a length")?;
            if length < 0.0 {
                return Err(ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::Expected { expected: "a non-negative length", found: length.to_string() },
                ));
            }
            bone.length = Some(length);
        }
        "axis" => {
            let mut rest = tokens;
            let mut angles = [0.0; 3];
            for slot in &mut angles {
                let token = rest.next().unwrap_or("");
                *slot = parse_number(file, line_no, token)?;
            }
            let order_token = rest.next().unwrap_or("");
            let order = parse_axis_order(order_token).ok_or_else(|| {
                ParseError::at(
                    file,
                    line_no,
                    ParseErrorKind::Expected { expected: "an Euler order such as XYZ", found: order_token.to_owned() },
                )
            })?;
            bone.axis = Some((angles, order));
        }
        "dof" => {
            let mut dofs = Vec::new();
            for token in tokens {
                let dof = Dof::parse(token).ok_or_else(|| {
                    ParseError::at(
                        file,
                        line_no,
                        ParseErrorKind::Expected { expected: "a DOF (rx ry rz tx ty tz l)", found: token.to_owned() },
                    )
                })?;
                if dofs.contains(&dof) {
                    return Err(ParseError::at(
                        file,
                        line_no,
                        ParseErrorKind::Invalid(format!("DOF `{token}` is listed twice")),
                    ));
                }
                dofs.push(dof);
            }
            bone.dofs = dofs;
        }
        "limits" => {
            bone.limits.clear();
            bone.limits_open = true;
            let rest = line.split_once(char::is_whitespace).map(|(_, r)| r).unwrap_or("");
            parse_limit_pairs(file, line_no, rest, &mut bone.limits)?;
        }
        // Present in some ASF exporters; no effect on kinematics.
        "bodymass" | "cofmass" => {}
        "end" => {
            let Some(done) = open.take() else { return Ok(None) };
            return finish_bone(file, line_no, done).map(Some);
        }
        _ => {
            return Err(ParseError::at(
                file,
                line_no,
                ParseErrorKind::Expected {
                    expected: "a bone field (id, name, direction, length, axis, dof, limits, end)",
                    found: line.to_owned(),
                },
            ));
        }
    }
    Ok(None)
}

fn finish_bone(file: &str, end_line: usize, b: BoneBuilder) -> Result<AsfBone, ParseError> {
    let missing = |field: &'static str| {
        ParseError::at(file, b.begin_line, ParseErrorKind::Invalid(format!("bone has no `{field}`")))
    };
    let name = b.name.clone().ok_or_else(|| missing("name"))?;
    let direction = b.direction.ok_or_else(|| missing("direction"))?;
    let length = b.length.ok_or_else(|| missing("length"))?;
    let (axis, axis_order) = b.axis.ok_or_else(|| missing("axis"))?;
    let norm = (direction[0] * direction[0] + direction[1] * direction[1] + direction[2] * direction[2]).sqrt();
    let direction = if norm > 1e-9 {
        direction.map(|v| v / norm)
    } else if length == 0.0 {
        [0.0; 3]
    } else {
        return Err(ParseError::at(
            file,
            b.begin_line,
            ParseErrorKind::Invalid(format!("bone `{name}` has a zero direction but length {length}")),
        ));
    };
    if !b.limits.is_empty() && b.limits.len() != b.dofs.len() {
        return Err(ParseError::at(
            file,
            end_line,
            ParseErrorKind::LimitCountMismatch { bone: name, dofs: b.dofs.len(), limits: b.limits.len() },
        ));
    }
    Ok(AsfBone { id: b.id, name, direction, length, axis, axis_order, dofs: b.dofs, limits: b.limits, parent: None })
}

fn resolve_hierarchy(
    file: &str,
    bones: &mut [AsfBone],
    links: &[(usize, String, Vec<String>)],
) -> Result<(), ParseError> {
    let index_of = |name: &str| bones.iter().position(|b| b.name == name);
    // None = not yet attached; Some(None) = child of the root; Some(Some(p)) = child of p.
    let mut parents: Vec<Option<Option<usize>>> = vec![None; bones.len()];
    let mut parent_line = vec![0usize; bones.len()];
    for (line, parent, children) in links {
        let parent_index = if parent.eq_ignore_ascii_case("root") {
            None
        } else {
            Some(
                index_of(parent)
                    .ok_or_else(|| ParseError::at(file, *line, ParseErrorKind::UnknownBone(parent.clone())))?,
            )
        };
        for child in children {
            let c = index_of(child)
                .ok_or_else(|| ParseError::at(file, *line, ParseErrorKind::UnknownBone(child.clone())))?;
            if let Some(existing) = parents[c] {
                let name = |p: Option<usize>| p.map_or_else(|| "root".to_owned(), |i| bones[i].name.clone());
                return Err(ParseError::at(
                    file,
                    *line,
                    ParseErrorKind::TwoParents { child: child.clone(), first: name(existing), second: parent.clone() },
                ));
            }
            parents[c] = Some(parent_index);
            parent_line[c] = *line;
        }
    }
    for (i, parent) in parents.iter().enumerate() {
        let Some(parent) = parent else {
            return Err(ParseError::in_file(file, ParseErrorKind::Unattached(bones[i].name.clone())));
        };
        bones[i].parent = *parent;
    }
    // Every chain of parents must reach the root within `bones.len()` steps.
    for start in 0..bones.len() {
        let mut current = bones[start].parent;
        let mut steps = 0;
        while let Some(p) = current {
            steps += 1;
            if steps > bones.len() {
                return Err(ParseError::at(file, parent_line[start], ParseErrorKind::Cycle(bones[start].name.clone())));
            }
            current = bones[p].parent;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    const MINI: &str = "\
:version 1.10
:name VICON
:units
  mass 1.0
  length 0.45
  angle deg
:documentation
   free text
:root
   order TX TY TZ RX RY RZ
   axis XYZ
   position 0 0 0
   orientation 0 0 0
:bonedata
  begin
     id 1
     name lfemur
     direction 0.34202 -0.939693 0
     length 7.5
     axis 0 0 20  XYZ
    dof rx ry rz
    limits (-160.0 20.0)
           (-70.0 70.0)
           (-60.0 inf)
  end
  begin
     id 2
     name ltibia
     direction 0.34202 -0.939693 0
     length 7.2
     axis 0 0 20 XYZ
    dof rx
    limits (-10.0 170.0)
  end
:hierarchy
  begin
    root lfemur
    lfemur ltibia
  end
";

    #[test]
    fn parses_a_small_skeleton() {
        let asf = AsfSkeleton::parse(MINI, "mini.asf").unwrap();
        assert_eq!(asf.name.as_deref(), Some("VICON"));
        assert_eq!(asf.units.length, 0.45);
        assert!((asf.units.metres_per_unit() - 0.056444).abs() < 1e-6);
        assert_eq!(asf.bones.len(), 2);
        let femur = &asf.bones[0];
        assert_eq!(femur.dofs, vec![Dof::Rotation(Axis::X), Dof::Rotation(Axis::Y), Dof::Rotation(Axis::Z)]);
        assert_eq!(femur.limits[2], (-60.0, f64::INFINITY));
        assert_eq!(femur.axis, [0.0, 0.0, 20.0]);
        assert_eq!(femur.parent, None);
        assert_eq!(asf.bones[1].parent, Some(0));
    }

    #[test]
    fn errors_name_the_line() {
        let bad = MINI.replace("length 7.2", "length seven");
        let err = AsfSkeleton::parse(&bad, "bad.asf").unwrap_err();
        assert_eq!(err.location.line, Some(MINI.lines().position(|l| l.contains("length 7.2")).unwrap() + 1));
        assert!(err.to_string().starts_with("bad.asf:"), "{err}");
        assert!(matches!(err.kind, ParseErrorKind::BadNumber(_)));
    }
}
