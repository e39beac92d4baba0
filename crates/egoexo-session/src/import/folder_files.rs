//! The files beside the devices' own in a session folder: an observer folder's placement and
//! keypoints, and the session's `subject.json`. Read by the Aria MPS importers.

use super::ImportOptions;
use crate::error::{ImportError, ImportWarning, Location};
use crate::format::STATIC_CAMERA_FILE;
use crate::json::JsonCtx;
use crate::keypoints::read_keypoints;
use crate::model::{KeypointTrack, SubjectInfo};
use crate::placement::{Mount, Placement};
use crate::vfs::FileTree;

/// File name of an observer folder's placement (its world and clock against the wearer's).
pub const PLACEMENT_FILE: &str = "placement.json";

/// An observer folder's [`PLACEMENT_FILE`] (`{"world": "own"}`, …; the `.egoexo` placement's
/// fields), or the default placement (the wearer's world and clock) without one.
pub(crate) fn read_placement_file(folder: &FileTree) -> Result<Placement, ImportError> {
    if !folder.contains(PLACEMENT_FILE) {
        return Ok(Placement::default());
    }
    let file = folder.display_path(PLACEMENT_FILE);
    let doc = JsonCtx::file(&file).parse(&folder.read_text(PLACEMENT_FILE)?)?;
    let placement: Placement = serde_json::from_value(doc.clone()).map_err(|e| {
        ImportError::invalid(
            &file,
            Location::File,
            format!("a placement {{world: shared|own, gravity, clock: shared|own, focal_known}} ({e})"),
            doc.to_string().chars().take(120).collect::<String>(),
        )
    })?;
    if placement.mount == Mount::Fixed {
        return Err(ImportError::invalid(
            &file,
            Location::Field("mount".into()),
            format!("`worn` for an MPS device folder (a static camera has a {STATIC_CAMERA_FILE})"),
            "`fixed`",
        ));
    }
    Ok(placement)
}

/// `keypoints.jsonl` or `keypoints.json` in an observer's folder, if any.
pub(crate) fn read_observer_keypoints(
    dir: &FileTree,
    id: &str,
    options: &ImportOptions,
    start_ns: i64,
    warnings: &mut Vec<ImportWarning>,
) -> Result<Option<KeypointTrack>, ImportError> {
    let candidates: Vec<&str> = ["keypoints.jsonl", "keypoints.json"].into_iter().filter(|f| dir.contains(f)).collect();
    let Some(&file) = candidates.first() else { return Ok(None) };
    if candidates.len() > 1 {
        warnings.push(ImportWarning {
            file: dir.display_path("keypoints.json"),
            message: "ignored: keypoints.jsonl is used".into(),
        });
    }
    let display = dir.display_path(file);
    let (track, more) = read_keypoints(&display, &dir.read_text(file)?, id, options.coco, start_ns)?;
    warnings.extend(more);
    Ok(Some(track))
}

/// `subject.json`: `{"height_m": 1.78, "betas": [..]}` (both optional).
pub(crate) fn read_subject_json(file: &str, text: &str) -> Result<SubjectInfo, ImportError> {
    let ctx = JsonCtx::file(file);
    let doc = ctx.parse(text)?;
    let height_m = match ctx.optional(&doc, "", "height_m")? {
        Some(v) => Some(ctx.f32(v, "height_m")?),
        None => None,
    };
    let betas = match ctx.optional(&doc, "", "betas")? {
        Some(v) => {
            let items = ctx.array(v, "betas")?;
            if items.is_empty() || items.len() > 300 {
                return Err(ctx.invalid("betas", "1 to 300 SMPL shape coefficients", v));
            }
            Some(items.iter().enumerate().map(|(i, b)| ctx.f32(b, &format!("betas[{i}]"))).collect::<Result<_, _>>()?)
        }
        None => None,
    };
    if let Some(h) = height_m
        && !crate::validate::STATURE_RANGE_M.contains(&h)
    {
        return Err(ImportError::invalid(
            file,
            Location::Field("height_m".into()),
            "a stature in metres within 0.5..=2.7",
            h.to_string(),
        ));
    }
    Ok(SubjectInfo { height_m, betas, rest_joints: None })
}
