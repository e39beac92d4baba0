//! Aria MPS importers: one device folder (the wearer's glasses alone) or a multi-device
//! session folder.
//!
//! # A device folder
//! The MPS output of one recording: `closed_loop_trajectory.csv` and (for the wearer's
//! glasses optional, for observers required) `online_calibration.jsonl`, either at the folder
//! root, in `slam/`, or in `mps/slam/` (or inside a single sub-folder such as
//! `mps_<name>_vrs/slam/`). An optional `time_sync.csv` (see [`crate::aria::time_sync`]) at
//! the folder root or next to the trajectory maps the device clock onto a common one.
//!
//! # The multi-device layout
//! ```text
//! <session>/
//!   wearer/                 device folder of the wearer's glasses (required)
//!   left_wrist/             device folder of a left-wrist device (optional)
//!   right_wrist/            device folder of a right-wrist device (optional)
//!   observers/<id>/         one device folder per observer; <id> becomes the observer id
//!     keypoints.jsonl       the observer's 2D keypoints (JSON lines), or
//!     keypoints.json        COCO-style keypoint JSON (optional)
//!   subject.json            {"height_m": 1.78} and/or {"betas": [...]} (optional)
//! ```
//! Either every device folder has a `time_sync.csv` or none does; without them all devices
//! must share the clock chosen by [`ImportOptions::clock`](super::ImportOptions).
//!
//! Conventions are converted here, once (see [`crate::aria`]): Z-up world → Y-up, device
//! frame → CPF for glasses (wrist devices keep their device frame: a wristband has no CPF),
//! `T_device_camera` → `T_cpf_camera`, microseconds → nanoseconds.

use egoexo_core::camera::CameraCalibration;
use egoexo_core::skeleton::DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE;

use super::ImportOptions;
use crate::aria::calibration::{RGB_LABEL, middle_record_with, read_online_calibration};
use crate::aria::time_sync::{TIME_SYNC_FILE, read_time_sync};
use crate::aria::trajectory::{Clock, WorldUp, read_closed_loop_trajectory};
use crate::aria::{AriaFrameSize, nominal_t_device_cpf, session_pose_from_aria};
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::json::JsonCtx;
use crate::keypoints::read_keypoints;
use crate::model::{Observer, Session, SubjectInfo, Trajectory, Wearer};
use crate::vfs::FileTree;

/// File name of an MPS closed-loop trajectory.
pub const TRAJECTORY_FILE: &str = "closed_loop_trajectory.csv";
/// File name of MPS online calibrations.
pub const CALIBRATION_FILE: &str = "online_calibration.jsonl";
/// Where a device folder may keep its MPS SLAM output.
pub const SLAM_DIRS: [&str; 3] = ["", "slam/", "mps/slam/"];

/// The files of one device folder (paths relative to the folder's view).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceFiles {
    pub trajectory: String,
    pub calibration: Option<String>,
    pub time_sync: Option<String>,
}

/// Finds the MPS files of a device folder; `None` if it has no trajectory.
pub fn find_device(dir: &FileTree) -> Result<Option<DeviceFiles>, ImportError> {
    let locate = |base: &str| -> Option<DeviceFiles> {
        SLAM_DIRS.iter().find_map(|slam| {
            let trajectory = format!("{base}{slam}{TRAJECTORY_FILE}");
            dir.contains(&trajectory).then(|| {
                let calibration = format!("{base}{slam}{CALIBRATION_FILE}");
                let time_sync = [format!("{base}{TIME_SYNC_FILE}"), format!("{base}{slam}{TIME_SYNC_FILE}")]
                    .into_iter()
                    .find(|p| dir.contains(p));
                DeviceFiles { trajectory, calibration: dir.contains(&calibration).then_some(calibration), time_sync }
            })
        })
    };
    if let Some(files) = locate("") {
        return Ok(Some(files));
    }
    let nested: Vec<DeviceFiles> = dir.subdirs("").into_iter().filter_map(|sub| locate(&format!("{sub}/"))).collect();
    match nested.len() {
        0 => Ok(None),
        1 => Ok(nested.into_iter().next()),
        _ => Err(ImportError::invalid(
            dir.display_path(""),
            Location::File,
            format!("one {TRAJECTORY_FILE} per device folder"),
            nested.iter().map(|f| dir.display_path(&f.trajectory)).collect::<Vec<_>>().join(", "),
        )),
    }
}

/// What a device is worn as.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DeviceRole {
    /// Glasses: poses become CPF poses.
    Head,
    /// Glasses of an observer: CPF poses and the RGB camera.
    Observer,
    /// A wrist device: the device frame is kept.
    Wrist,
}

/// A device in session conventions.
#[derive(Clone, Debug)]
pub(crate) struct LoadedDevice {
    pub trajectory: Trajectory,
    /// `T_cpf_camera` of the RGB camera (observers).
    pub camera: Option<CameraCalibration>,
    /// Whether a `time_sync.csv` put it on the common clock.
    pub synced: bool,
}

/// Reads and converts one device folder.
pub(crate) fn load_device(
    dir: &FileTree,
    role: DeviceRole,
    clock: Clock,
    warnings: &mut Vec<ImportWarning>,
) -> Result<LoadedDevice, ImportError> {
    let files = find_device(dir)?.ok_or_else(|| {
        ImportError::missing_file(
            dir.display_path(TRAJECTORY_FILE),
            format!("an Aria MPS device folder with {TRAJECTORY_FILE} (at its root, in slam/ or in mps/slam/)"),
        )
    })?;
    let records = match &files.calibration {
        Some(path) => Some(read_online_calibration(&dir.display_path(path), &dir.read_text(path)?)?),
        None => None,
    };
    // Where the calibration is (or, when missing, would be): next to the trajectory.
    let calibration_name = || match &files.calibration {
        Some(path) => dir.display_path(path),
        None => {
            let slam_dir = files.trajectory.strip_suffix(TRAJECTORY_FILE).unwrap_or_default();
            dir.display_path(&format!("{slam_dir}{CALIBRATION_FILE}"))
        }
    };
    let (t_device_cpf, camera) = match (&records, role) {
        (Some(records), _) => {
            let middle = &records[records.len() / 2];
            let camera = if role == DeviceRole::Observer {
                let (record, rgb) = middle_record_with(&calibration_name(), records, RGB_LABEL)?;
                let t_device_cpf = record.t_device_cpf();
                let mut camera = rgb.calibration;
                camera.t_device_camera = t_device_cpf.inverse() * rgb.calibration.t_device_camera;
                Some(camera)
            } else {
                None
            };
            (middle.t_device_cpf(), camera)
        }
        (None, DeviceRole::Observer) => {
            return Err(ImportError::missing_file(
                calibration_name(),
                "the observer's MPS online_calibration.jsonl (its RGB camera calibration)",
            ));
        }
        (None, DeviceRole::Head) => {
            warnings.push(ImportWarning {
                file: calibration_name(),
                message: "missing; used the nominal Aria DVT-S T_device_cpf".into(),
            });
            (nominal_t_device_cpf(AriaFrameSize::Small), None)
        }
        (None, DeviceRole::Wrist) => (nominal_t_device_cpf(AriaFrameSize::Small), None),
    };

    let trajectory_file = dir.display_path(&files.trajectory);
    let raw = read_closed_loop_trajectory(&trajectory_file, &dir.read(&files.trajectory)?, clock, WorldUp::Z)?;
    let mut timestamps_ns = raw.timestamps_ns;
    let synced = match (&files.time_sync, clock) {
        (Some(path), Clock::Device) => {
            let sync_file = dir.display_path(path);
            let sync = read_time_sync(&sync_file, &dir.read(path)?)?;
            for (i, t) in timestamps_ns.iter_mut().enumerate() {
                *t = sync.map(*t).ok_or_else(|| {
                    ImportError::invalid(
                        &sync_file,
                        Location::File,
                        "a mapping that stays within i64 nanoseconds",
                        format!("overflow at pose {i}"),
                    )
                })?;
            }
            if let Some(i) = timestamps_ns.windows(2).position(|w| w[1] <= w[0]) {
                return Err(ImportError::invalid(
                    &sync_file,
                    Location::File,
                    format!("a mapping that keeps the poses of {trajectory_file} strictly increasing"),
                    format!("poses {} and {} map to {} and {}", i, i + 1, timestamps_ns[i], timestamps_ns[i + 1]),
                ));
            }
            true
        }
        (Some(path), Clock::Utc) => {
            warnings.push(ImportWarning {
                file: dir.display_path(path),
                message: "ignored: it maps the device clock, but the UTC clock was chosen".into(),
            });
            false
        }
        (None, _) => false,
    };
    let cpf = match role {
        DeviceRole::Head | DeviceRole::Observer => Some(&t_device_cpf),
        DeviceRole::Wrist => None,
    };
    let poses = raw.poses.iter().map(|p| session_pose_from_aria(p, cpf)).collect();
    Ok(LoadedDevice { trajectory: Trajectory { timestamps_ns, poses }, camera, synced })
}

/// Loads the device folders of one multi-device recording (the Aria multi-device layout,
/// Nymeria) and checks at the end that either all or none of them were on a common clock.
pub(crate) struct DeviceLoader<'w> {
    clock: Clock,
    warnings: &'w mut Vec<ImportWarning>,
    /// `(folder, synced)` per loaded device, in load order.
    synced: Vec<(String, bool)>,
}

impl<'w> DeviceLoader<'w> {
    pub(crate) fn new(clock: Clock, warnings: &'w mut Vec<ImportWarning>) -> Self {
        Self { clock, warnings, synced: Vec::new() }
    }

    /// Loads the device folder `dir` of `root`.
    pub(crate) fn device(&mut self, root: &FileTree, dir: &str, role: DeviceRole) -> Result<LoadedDevice, ImportError> {
        let device = load_device(&root.view(dir), role, self.clock, self.warnings)?;
        self.synced.push((format!("{dir}/"), device.synced));
        Ok(device)
    }

    /// The wearer's glasses in `head_dir` and, where those folders exist, the wrist devices in
    /// `wrist_dirs` (left, right).
    pub(crate) fn wearer(
        &mut self,
        root: &FileTree,
        head_dir: &str,
        wrist_dirs: [&str; 2],
    ) -> Result<(LoadedDevice, [Option<Trajectory>; 2]), ImportError> {
        let head = self.device(root, head_dir, DeviceRole::Head)?;
        let mut wrists = [None, None];
        for (slot, dir) in wrists.iter_mut().zip(wrist_dirs) {
            if root.contains_dir(dir) {
                *slot = Some(self.device(root, dir, DeviceRole::Wrist)?.trajectory);
            }
        }
        Ok((head, wrists))
    }

    /// The observer `id` in the device folder `dir` of `root`: its trajectory, its RGB camera
    /// and its keypoints (`keypoints.jsonl` or `keypoints.json`, when present).
    pub(crate) fn observer(
        &mut self,
        root: &FileTree,
        dir: &str,
        id: &str,
        options: &ImportOptions,
    ) -> Result<Observer, ImportError> {
        let device = self.device(root, dir, DeviceRole::Observer)?;
        let folder = root.view(dir);
        let camera = device.camera.ok_or_else(|| {
            ImportError::missing_file(folder.display_path(CALIBRATION_FILE), "the observer's RGB camera calibration")
        })?;
        let start = device.trajectory.timestamps_ns.first().copied().unwrap_or_default();
        let keypoints = read_observer_keypoints(&folder, id, options, start, self.warnings)?;
        Ok(Observer {
            id: id.to_owned(),
            head: device.trajectory,
            camera,
            keypoints,
            video: None,
            context_features: None,
        })
    }

    /// Errors unless every device was synced or none was; returns whether they were.
    pub(crate) fn finish(self) -> Result<bool, ImportError> {
        let (synced, unsynced): (Vec<_>, Vec<_>) = self.synced.iter().partition(|(_, s)| *s);
        if let (Some((with, _)), Some((without, _))) = (synced.first(), unsynced.first()) {
            return Err(ImportError::new(
                without.clone(),
                Location::File,
                ImportErrorKind::MixedClocks {
                    detail: format!(
                        "`{with}` has a {TIME_SYNC_FILE} (common clock) but `{without}` has none (device clock); give every device folder one, or none"
                    ),
                },
            ));
        }
        Ok(unsynced.is_empty() && !synced.is_empty())
    }
}

/// Imports one device folder: the wearer's glasses alone.
pub fn import_single_device(
    root: &FileTree,
    name: &str,
    options: &ImportOptions,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let mut warnings = Vec::new();
    let head = load_device(root, DeviceRole::Head, options.clock, &mut warnings)?;
    warnings.push(ImportWarning {
        file: root.display_path(""),
        message: "one device: a session without observers (add observers with the multi-device layout)".into(),
    });
    let session = Session {
        name: name.to_owned(),
        wearer: wearer(head.trajectory, None, None),
        observers: Vec::new(),
        subject: SubjectInfo::default(),
        ground_truth: None,
    };
    Ok((session, warnings))
}

fn wearer(head: Trajectory, left_wrist: Option<Trajectory>, right_wrist: Option<Trajectory>) -> Wearer {
    Wearer { head, left_wrist, right_wrist, head_joint_in_device: DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE }
}

/// Imports the multi-device layout (see the module docs).
pub fn import_multi_device(
    root: &FileTree,
    name: &str,
    options: &ImportOptions,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let mut warnings = Vec::new();
    let mut devices = DeviceLoader::new(options.clock, &mut warnings);
    let (head, wrists) = devices.wearer(root, "wearer", ["left_wrist", "right_wrist"])?;
    let mut observers = Vec::new();
    for id in root.subdirs("observers") {
        let dir = format!("observers/{id}");
        if !crate::validate::is_valid_observer_id(&id) {
            return Err(ImportError::invalid(
                root.view(&dir).display_path(""),
                Location::File,
                "an observer folder name of 1–64 characters from A–Z, a–z, 0–9, `.`, `_`, `-`",
                format!("`{id}`"),
            ));
        }
        observers.push(devices.observer(root, &dir, &id, options)?);
    }
    devices.finish()?;
    if observers.is_empty() {
        warnings.push(ImportWarning {
            file: root.display_path("observers/"),
            message: "no observer folders: a session without observers".into(),
        });
    }
    for top in root.subdirs("") {
        if !matches!(top.as_str(), "wearer" | "left_wrist" | "right_wrist" | "observers") {
            warnings.push(ImportWarning {
                file: root.display_path(&top),
                message: "ignored (not part of the layout)".into(),
            });
        }
    }
    let subject = if root.contains("subject.json") {
        read_subject_json(&root.display_path("subject.json"), &root.read_text("subject.json")?)?
    } else {
        warnings.push(ImportWarning {
            file: root.display_path("subject.json"),
            message: "missing; the wearer gets the mean SMPL body shape".into(),
        });
        SubjectInfo::default()
    };
    let [left_wrist, right_wrist] = wrists;
    let session = Session {
        name: name.to_owned(),
        wearer: wearer(head.trajectory, left_wrist, right_wrist),
        observers,
        subject,
        ground_truth: None,
    };
    Ok((session, warnings))
}

/// `keypoints.jsonl` or `keypoints.json` in an observer's folder, if any.
pub(crate) fn read_observer_keypoints(
    dir: &FileTree,
    id: &str,
    options: &ImportOptions,
    start_ns: i64,
    warnings: &mut Vec<ImportWarning>,
) -> Result<Option<crate::model::KeypointTrack>, ImportError> {
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
