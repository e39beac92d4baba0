//! Aria MPS importers: one device folder (the wearer's glasses alone) or a multi-device
//! session folder.
//!
//! # A device folder
//! The MPS output of one recording: `closed_loop_trajectory.csv` and (for the wearer's
//! glasses optional, for observers required) `online_calibration.jsonl`, either at the folder
//! root, in `slam/` or `trajectory/`, or in `mps/slam/` or `mps/trajectory/` (or inside a
//! single sub-folder such as `mps_<name>_vrs/slam/`). An optional `time_sync.csv` (see
//! [`crate::aria::time_sync`]) at the folder root or next to the trajectory maps the device
//! clock onto a common one. Next to the trajectory, semidense points
//! ([`crate::aria::semidense`]) give the floor; MPS hand tracking of the wearer's glasses
//! (`hand_tracking/` beside the trajectory's folder, [`crate::aria::hand_tracking`]) gives
//! the wrists when there are no wrist devices.
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
//!     placement.json        its world and clock when not the others' (optional: e.g.
//!                           `{"world": "own"}` for glasses MPS localised alone)
//!     static_camera.json    instead of MPS output: a static camera (its calibration and pose,
//!                           or none to register it; `crate::format::read_static_camera`)
//!   subject.json            {"height_m": 1.78} and/or {"betas": [...]} (optional)
//! ```
//! Either every device folder has a `time_sync.csv` or none does; without them all devices
//! must share the clock chosen by [`ImportOptions::clock`](super::ImportOptions).
//!
//! Conventions are converted here, once (see [`crate::aria`]): the file's world (its gravity
//! says which way is down) → Y-up, device frame → CPF for glasses (wrist devices keep their device frame: a wristband has no CPF),
//! `T_device_camera` → `T_cpf_camera`, microseconds → nanoseconds.

use egoexo_core::camera::CameraCalibration;
use egoexo_core::glam::Vec3;
use egoexo_core::skeleton::DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE;

use super::ImportOptions;
pub use super::folder_files::PLACEMENT_FILE;
use super::folder_files::{read_observer_keypoints, read_placement_file, read_subject_json};
use crate::aria::calibration::{CalibrationRecord, RGB_LABEL, middle_record_with, read_online_calibration};
use crate::aria::hand_tracking::{
    HAND_TRACKING_DIR, HAND_TRACKING_RESULTS_FILE, HandTracking, Side, WRIST_AND_PALM_FILE, read_hand_tracking,
    t_device_wrist,
};
use crate::aria::semidense::{SEMIDENSE_FILES, SemidenseHeights, read_semidense_heights};
use crate::aria::time_sync::{TIME_SYNC_FILE, TimeSync, read_time_sync};
use crate::aria::trajectory::{Clock, CsvTrajectory, read_closed_loop_trajectory};
use crate::aria::{AriaFrameSize, nominal_t_device_cpf, session_pose_from_file, t_session_world_from_gravity};
use crate::capture::spread_fixed_poses;
use crate::error::{ImportError, ImportErrorKind, ImportWarning, Location};
use crate::floor::{Floor, floor_from_points};
use crate::format::{STATIC_CAMERA_FILE, read_static_camera};
use crate::model::{Observer, Session, SubjectInfo, Trajectory, VideoRef, Wearer, WristSource};
use crate::vfs::FileTree;

/// File name of an MPS closed-loop trajectory.
pub const TRAJECTORY_FILE: &str = "closed_loop_trajectory.csv";
/// File name of MPS online calibrations.
pub const CALIBRATION_FILE: &str = "online_calibration.jsonl";
/// Where a device folder may keep its MPS SLAM output (`trajectory/` is the name MPS's own
/// output folders use, `slam/` the datasets').
pub const SLAM_DIRS: [&str; 5] = ["", "slam/", "trajectory/", "mps/slam/", "mps/trajectory/"];

/// The files of one device folder (paths relative to the folder's view).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DeviceFiles {
    pub trajectory: String,
    pub calibration: Option<String>,
    pub time_sync: Option<String>,
    /// Semidense points next to the trajectory.
    pub semidense: Option<String>,
    /// Hand tracking: `hand_tracking_results.csv` (preferred: full wrist poses) or
    /// `wrist_and_palm_poses.csv`, in `hand_tracking/` beside the trajectory's folder.
    pub hand_tracking: Option<String>,
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
                let semidense = SEMIDENSE_FILES.iter().map(|f| format!("{base}{slam}{f}")).find(|p| dir.contains(p));
                // `hand_tracking/` is a sibling of the SLAM folder (`mps/slam/` → `mps/hand_tracking/`).
                let mps_root = slam.strip_suffix("slam/").or_else(|| slam.strip_suffix("trajectory/")).unwrap_or(slam);
                let hand_tracking = [HAND_TRACKING_RESULTS_FILE, WRIST_AND_PALM_FILE]
                    .iter()
                    .map(|f| format!("{base}{mps_root}{HAND_TRACKING_DIR}{f}"))
                    .find(|p| dir.contains(p));
                DeviceFiles {
                    trajectory,
                    calibration: dir.contains(&calibration).then_some(calibration),
                    time_sync,
                    semidense,
                    hand_tracking,
                }
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

/// The RGB camera of a device's online calibrations (the middle record's), mounted on CPF.
fn rgb_camera(
    file: &str,
    records: &[CalibrationRecord],
    warnings: &mut Vec<ImportWarning>,
) -> Result<CameraCalibration, ImportError> {
    let (record, rgb) = middle_record_with(file, records, RGB_LABEL)?;
    if !rgb.size_from_image_sizes {
        let c = &rgb.calibration;
        warnings.push(ImportWarning {
            file: file.to_owned(),
            message: format!(
                "no ImageSizes (an MPS < 1.1 calibration): the RGB camera is taken at the sensor's full {}×{} px; keypoints are read in those pixels unless they show a smaller image",
                c.width, c.height
            ),
        });
    }
    let t_device_cpf = record.t_device_cpf();
    let mut camera = rgb.calibration;
    camera.t_device_camera = t_device_cpf.inverse() * rgb.calibration.t_device_camera;
    Ok(camera)
}

/// The RGB camera of the device folder `dir` (its MPS online calibration alone, without the
/// trajectory): for a wearer whose glasses also saw the others.
pub(crate) fn device_rgb_camera(
    dir: &FileTree,
    warnings: &mut Vec<ImportWarning>,
) -> Result<CameraCalibration, ImportError> {
    let files = find_device(dir)?.ok_or_else(|| {
        ImportError::missing_file(dir.display_path(TRAJECTORY_FILE), "the device's MPS closed-loop trajectory")
    })?;
    let Some(path) = files.calibration else {
        let slam_dir = files.trajectory.strip_suffix(TRAJECTORY_FILE).unwrap_or_default();
        return Err(ImportError::missing_file(
            dir.display_path(&format!("{slam_dir}{CALIBRATION_FILE}")),
            "the device's MPS online_calibration.jsonl (its RGB camera calibration)",
        ));
    };
    let file = dir.display_path(&path);
    let records = read_online_calibration(&file, &dir.read_text(&path)?)?;
    rgb_camera(&file, &records, warnings)
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
    /// The wearer's wrists from MPS hand tracking (head devices with hand tracking).
    pub hand_wrists: Option<([Option<Trajectory>; 2], WristSource)>,
    /// The floor from semidense points (head devices with points that show one).
    pub floor: Option<Floor>,
    /// The RGB stream as MP4 with its frames' times on the session clock (observers that
    /// bring one, [`crate::video::find_device_video`]).
    pub video: Option<VideoRef>,
}

/// Reads and converts one device folder.
pub(crate) fn load_device(
    dir: &FileTree,
    role: DeviceRole,
    options: &ImportOptions,
    warnings: &mut Vec<ImportWarning>,
) -> Result<LoadedDevice, ImportError> {
    let clock = options.clock;
    let files = find_device(dir)?.ok_or_else(|| {
        ImportError::missing_file(
            dir.display_path(TRAJECTORY_FILE),
            format!(
                "an Aria MPS device folder with {TRAJECTORY_FILE} (at its root, or in slam/, trajectory/, mps/slam/ or mps/trajectory/)"
            ),
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
                Some(rgb_camera(&calibration_name(), records, warnings)?)
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
    let size = dir.size(&files.trajectory).unwrap_or(0);
    let raw = read_closed_loop_trajectory(
        &trajectory_file,
        dir.open_reader(&files.trajectory)?,
        clock,
        &mut options.progress_of(&trajectory_file, size),
    )?;
    warn_low_quality(&trajectory_file, &raw, warnings);
    let t_session_file = t_session_world_from_gravity(raw.gravity_world);
    let sync = match (&files.time_sync, clock) {
        (Some(path), Clock::Device) => {
            let sync_file = dir.display_path(path);
            Some((read_time_sync(&sync_file, &dir.read(path)?)?, sync_file))
        }
        (Some(path), Clock::Utc) => {
            warnings.push(ImportWarning {
                file: dir.display_path(path),
                message: "ignored: it maps the device clock, but the UTC clock was chosen".into(),
            });
            None
        }
        (None, _) => None,
    };
    // The device (not CPF) in the session world, on the file's clock: hand tracking is
    // expressed with it before any clock mapping.
    // Converted in place (an hour at 1 kHz is 3.6 M poses): first the device (not CPF) in the
    // session world, on the file's clock — hand tracking is expressed with it before any clock
    // mapping — then CPF and the common clock.
    let CsvTrajectory { timestamps_ns, mut poses, .. } = raw;
    for pose in &mut poses {
        *pose = session_pose_from_file(&t_session_file, pose, None);
    }
    let mut trajectory = Trajectory { timestamps_ns, poses };
    let hand_wrists = match (&files.hand_tracking, role) {
        (Some(path), DeviceRole::Head) => {
            let file = dir.display_path(path);
            if clock == Clock::Utc {
                warnings.push(ImportWarning {
                    file,
                    message: "ignored: hand tracking is timed on the device clock, but the UTC clock was chosen".into(),
                });
                None
            } else {
                let hands = read_hand_tracking(&file, dir.open_reader(path)?)?;
                let mut wrists = wrists_in_world(&hands, &trajectory, warnings, &file);
                if let Some((sync, sync_file)) = &sync {
                    for wrist in wrists.iter_mut().flatten() {
                        map_clock(&mut wrist.timestamps_ns, sync, sync_file, &file)?;
                    }
                }
                let source = WristSource::HandTracking { file, form: hands.form, orientation: hands.orientation() };
                Some((wrists, source))
            }
        }
        _ => None,
    };
    let synced = match &sync {
        Some((sync, sync_file)) => {
            map_clock(&mut trajectory.timestamps_ns, sync, sync_file, &trajectory_file)?;
            true
        }
        None => false,
    };
    if matches!(role, DeviceRole::Head | DeviceRole::Observer) {
        for pose in &mut trajectory.poses {
            *pose = *pose * t_device_cpf;
        }
    }
    let floor = match (&files.semidense, role) {
        (Some(path), DeviceRole::Head) => {
            let file = dir.display_path(path);
            let SemidenseHeights { heights, rows } = read_semidense_heights(
                &file,
                dir.open_reader(path)?,
                &t_session_file,
                &mut options.progress_of(&file, 0),
            )?;
            let floor = floor_from_points(&heights, &trajectory, &file);
            if floor.is_none() {
                warnings.push(ImportWarning {
                    file,
                    message: format!(
                        "{} of {rows} points are well constrained, but none form a floor {}–{} m below the standing head; the floor is estimated from the standing head instead",
                        heights.count(),
                        crate::floor::MIN_EYE_HEIGHT_M,
                        crate::floor::MAX_EYE_HEIGHT_M
                    ),
                });
            }
            floor
        }
        _ => None,
    };
    let video = match role {
        DeviceRole::Observer => device_video(dir, clock, sync.as_ref(), warnings)?,
        _ => None,
    };
    Ok(LoadedDevice { trajectory, camera, synced, hand_wrists, floor, video })
}

/// An observer folder's MP4 and its frames' capture times on the session clock (mapped by the
/// device's `time_sync.csv` like its trajectory); `None` without a video, or on the UTC clock
/// (capture times are device-clock times; a warning says the video was left out).
fn device_video(
    dir: &FileTree,
    clock: Clock,
    sync: Option<&(TimeSync, String)>,
    warnings: &mut Vec<ImportWarning>,
) -> Result<Option<VideoRef>, ImportError> {
    let Some((video, timestamps)) = crate::video::find_device_video(dir)? else { return Ok(None) };
    if clock == Clock::Utc {
        warnings.push(ImportWarning {
            file: dir.display_path(&video),
            message: "left out: its frames are timed on the device clock, but the UTC clock was chosen".into(),
        });
        return Ok(None);
    }
    let file = dir.display_path(&timestamps);
    let mut times =
        crate::video::read_frame_timestamps(&file, &dir.read(&timestamps)?, crate::video::CAPTURE_TIMESTAMP_COLUMN)?;
    if let Some((sync, sync_file)) = sync {
        map_clock(&mut times, sync, sync_file, &file)?;
    }
    // The path inside the device folder; `DeviceLoader::observer` makes it the session root's.
    Ok(Some(VideoRef { path: video, start_ns: times[0], frame_times_ns: times }))
}

/// Maps `timestamps` (of `what`) onto the common clock of `sync`; they must stay strictly
/// increasing.
fn map_clock(timestamps: &mut [i64], sync: &TimeSync, sync_file: &str, what: &str) -> Result<(), ImportError> {
    for (i, t) in timestamps.iter_mut().enumerate() {
        *t = sync.map(*t).ok_or_else(|| {
            ImportError::invalid(
                sync_file,
                Location::File,
                "a mapping that stays within i64 nanoseconds",
                format!("overflow at sample {i} of {what}"),
            )
        })?;
    }
    if let Some(i) = timestamps.windows(2).position(|w| w[1] <= w[0]) {
        return Err(ImportError::invalid(
            sync_file,
            Location::File,
            format!("a mapping that keeps the samples of {what} strictly increasing"),
            format!("samples {} and {} map to {} and {}", i, i + 1, timestamps[i], timestamps[i + 1]),
        ));
    }
    Ok(())
}

/// Tells the user about runs of low `quality_score` (kept, but worth knowing).
fn warn_low_quality(file: &str, raw: &CsvTrajectory, warnings: &mut Vec<ImportWarning>) {
    if raw.low_quality.is_empty() {
        return;
    }
    let start = raw.timestamps_ns[0];
    let rows: usize = raw.low_quality.iter().map(|s| s.rows).sum();
    let seconds = |t: i64| (t - start) as f64 / 1e9;
    let mut spans: Vec<String> = raw
        .low_quality
        .iter()
        .take(5)
        .map(|s| format!("{:.2}–{:.2} s", seconds(s.start_ns), seconds(s.end_ns)))
        .collect();
    if raw.low_quality.len() > 5 {
        spans.push(format!("and {} more", raw.low_quality.len() - 5));
    }
    warnings.push(ImportWarning {
        file: file.to_owned(),
        message: format!(
            "{rows} of {} poses have quality_score below {} ({} after the start); they are kept, but the head may be off there",
            raw.poses.len(),
            crate::aria::trajectory::LOW_QUALITY_SCORE,
            spans.join(", ")
        ),
    });
}

/// MPS hand observations (device frame, device clock) → wrist trajectories in the session
/// world with the head device's trajectory `device` (session world, device frame, same
/// clock) interpolated at each sample's time. Samples outside the trajectory or in a gap of
/// it, and hands with no direction (wrist and palm on top of each other), are left out.
fn wrists_in_world(
    hands: &HandTracking,
    device: &Trajectory,
    warnings: &mut Vec<ImportWarning>,
    file: &str,
) -> [Option<Trajectory>; 2] {
    let mut dropped = 0usize;
    let mut out = [None, None];
    for (slot, side) in out.iter_mut().zip([Side::Left, Side::Right]) {
        let samples = hands.hand(side);
        let at = crate::align::resample_trajectory(device, &samples.timestamps_ns, crate::align::DEFAULT_MAX_GAP_NS);
        let mut wrist = Trajectory::default();
        for ((&t, observation), (t_world_device, &valid)) in
            samples.timestamps_ns.iter().zip(&samples.observations).zip(at.poses.iter().zip(&at.valid))
        {
            let down_device = t_world_device.rotation.conjugate() * Vec3::NEG_Y;
            match t_device_wrist(side, observation, down_device) {
                Some(t_device_wrist) if valid => {
                    wrist.timestamps_ns.push(t);
                    wrist.poses.push(*t_world_device * t_device_wrist);
                }
                _ => dropped += 1,
            }
        }
        *slot = (!wrist.is_empty()).then_some(wrist);
    }
    if dropped > 0 {
        warnings.push(ImportWarning {
            file: file.to_owned(),
            message: format!(
                "{dropped} tracked hand samples left out: outside the head trajectory, in a gap of it, or with the wrist on the palm"
            ),
        });
    }
    let tracked = |side| hands.hand(side).timestamps_ns.len() as f64 / hands.rows.max(1) as f64 * 100.0;
    warnings.push(ImportWarning {
        file: file.to_owned(),
        message: format!(
            "wrists from hand tracking ({}): left hand tracked on {:.0}% of {} rows, right on {:.0}%",
            hands.form.describe(),
            tracked(Side::Left),
            hands.rows,
            tracked(Side::Right)
        ),
    });
    out
}

/// The wearer's devices: glasses and wrists (left, right).
pub(crate) struct LoadedWearer {
    pub head: LoadedDevice,
    pub wrists: [Option<Trajectory>; 2],
    pub wrist_source: WristSource,
}

impl LoadedWearer {
    /// The session's wearer.
    pub(crate) fn into_wearer(self) -> (Wearer, Option<Floor>) {
        let [left_wrist, right_wrist] = self.wrists;
        let wearer = Wearer {
            head: self.head.trajectory,
            left_wrist,
            right_wrist,
            wrist_source: self.wrist_source,
            head_joint_in_device: DEFAULT_HEAD_JOINT_IN_HEAD_DEVICE,
        };
        (wearer, self.head.floor)
    }
}

/// Loads the device folders of one multi-device recording (the Aria multi-device layout,
/// Nymeria) and checks at the end that either all or none of them were on a common clock.
pub(crate) struct DeviceLoader<'w> {
    options: &'w ImportOptions,
    warnings: &'w mut Vec<ImportWarning>,
    /// `(folder, synced)` per loaded device, in load order.
    synced: Vec<(String, bool)>,
}

impl<'w> DeviceLoader<'w> {
    pub(crate) fn new(options: &'w ImportOptions, warnings: &'w mut Vec<ImportWarning>) -> Self {
        Self { options, warnings, synced: Vec::new() }
    }

    /// Loads the device folder `dir` of `root`.
    pub(crate) fn device(&mut self, root: &FileTree, dir: &str, role: DeviceRole) -> Result<LoadedDevice, ImportError> {
        let device = load_device(&root.view(dir), role, self.options, self.warnings)?;
        self.synced.push((format!("{dir}/"), device.synced));
        Ok(device)
    }

    /// The wearer's glasses in `head_dir` and their wrists: the wrist devices in `wrist_dirs`
    /// (left, right) where those folders exist, else the glasses' MPS hand tracking.
    pub(crate) fn wearer(
        &mut self,
        root: &FileTree,
        head_dir: &str,
        wrist_dirs: [&str; 2],
    ) -> Result<LoadedWearer, ImportError> {
        let mut head = self.device(root, head_dir, DeviceRole::Head)?;
        let mut wrists = [None, None];
        for (slot, dir) in wrists.iter_mut().zip(wrist_dirs) {
            if root.contains_dir(dir) {
                *slot = Some(self.device(root, dir, DeviceRole::Wrist)?.trajectory);
            }
        }
        let mut wrist_source = WristSource::Devices;
        if let Some((tracked, source)) = head.hand_wrists.take() {
            if wrists.iter().any(Option::is_some) {
                if let WristSource::HandTracking { file, .. } = &source {
                    self.warnings.push(ImportWarning {
                        file: file.clone(),
                        message: "ignored: the wrist devices are used".into(),
                    });
                }
            } else {
                wrists = tracked;
                wrist_source = source;
            }
        }
        Ok(LoadedWearer { head, wrists, wrist_source })
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
        let placement = read_placement_file(&folder)?;
        Ok(Observer {
            id: id.to_owned(),
            head: device.trajectory,
            camera,
            keypoints,
            video: device.video.map(|mut video| {
                let dir = dir.trim_end_matches('/');
                if !dir.is_empty() {
                    video.path = format!("{dir}/{}", video.path);
                }
                video
            }),
            context_features: None,
            placement,
        })
    }

    /// The static camera `id` in the observer folder `dir` of `root`
    /// ([`STATIC_CAMERA_FILE`] and its keypoints, on the session clock; COCO frame numbers
    /// count from `start_ns`, the wearer's first pose). No MPS output may sit beside it.
    pub(crate) fn static_camera(
        &mut self,
        root: &FileTree,
        dir: &str,
        id: &str,
        start_ns: i64,
    ) -> Result<Observer, ImportError> {
        let folder = root.view(dir);
        let mps = folder.paths().into_iter().find(|p| {
            let name = p.rsplit('/').next().unwrap_or(p);
            name == TRAJECTORY_FILE || name == CALIBRATION_FILE
        });
        if let Some(found) = mps {
            return Err(ImportError::invalid(
                folder.display_path(STATIC_CAMERA_FILE),
                Location::File,
                "a static camera's folder without MPS output, or an MPS device folder without a static camera file",
                format!("both {STATIC_CAMERA_FILE} and {found}"),
            ));
        }
        let (camera, head, placement, warnings) = read_static_camera(&folder, STATIC_CAMERA_FILE)?;
        self.warnings.extend(warnings);
        let keypoints = read_observer_keypoints(&folder, id, self.options, start_ns, self.warnings)?;
        if keypoints.is_none() {
            self.warnings.push(ImportWarning {
                file: folder.display_path(""),
                message: "a static camera without keypoints: it sees nothing the reconstruction can use".into(),
            });
        }
        Ok(Observer { id: id.to_owned(), head, camera, keypoints, video: None, context_features: None, placement })
    }

    /// How many device folders were loaded (static cameras, which have no clock of their own
    /// here, not counted).
    pub(crate) fn loaded(&self) -> usize {
        self.synced.len()
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
    let mut head = load_device(root, DeviceRole::Head, options, &mut warnings)?;
    warnings.push(ImportWarning {
        file: root.display_path(""),
        message: "one device: a session without observers (add observers with the multi-device layout)".into(),
    });
    let (wrists, wrist_source) = head.hand_wrists.take().unwrap_or_default();
    let (wearer, floor) = LoadedWearer { head, wrists, wrist_source }.into_wearer();
    let session = Session {
        name: name.to_owned(),
        wearer,
        observers: Vec::new(),
        subject: SubjectInfo::default(),
        ground_truth: None,
        floor,
    };
    Ok((session, warnings))
}

/// What the import assumed when no device folder has a `time_sync.csv`: that the devices'
/// timestamps of `clock` are one clock. True of the streams of one device, and of devices
/// recorded on a shared clock; for glasses recorded on their own (MPS processes each alone),
/// their samples would be paired across an unknown offset.
fn unsynced_clocks_warning(root: &FileTree, devices: usize, clock: Clock) -> ImportWarning {
    let assumed = match clock {
        Clock::Device => "the devices' own clocks (`tracking_timestamp_us`) are taken as one clock: true only for \
            devices recorded on a shared clock (Aria glasses recording together with TimeCode or SubGHz sync); \
            for glasses recorded on their own, give every device folder its time_sync.csv, or import with \
            `--clock utc`"
            .to_string(),
        Clock::Utc => "their UTC timestamps are taken as one clock: as good as the devices' wall clocks agreed \
            when they recorded"
            .to_string(),
    };
    ImportWarning {
        file: root.display_path(""),
        message: format!("no device folder has a {TIME_SYNC_FILE}: {devices} devices, and {assumed}"),
    }
}

/// Imports the multi-device layout (see the module docs).
pub fn import_multi_device(
    root: &FileTree,
    name: &str,
    options: &ImportOptions,
) -> Result<(Session, Vec<ImportWarning>), ImportError> {
    let mut warnings = Vec::new();
    let mut devices = DeviceLoader::new(options, &mut warnings);
    let (wearer, floor) = devices.wearer(root, "wearer", ["left_wrist", "right_wrist"])?.into_wearer();
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
        if root.view(&dir).contains(STATIC_CAMERA_FILE) {
            let start_ns = wearer.head.timestamps_ns.first().copied().unwrap_or_default();
            observers.push(devices.static_camera(root, &dir, &id, start_ns)?);
        } else {
            observers.push(devices.observer(root, &dir, &id, options)?);
        }
    }
    let devices_loaded = devices.loaded();
    let synced = devices.finish()?;
    if !synced && devices_loaded > 1 {
        warnings.push(unsynced_clocks_warning(root, devices_loaded, options.clock));
    }
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
    let mut session = Session { name: name.to_owned(), wearer, observers, subject, ground_truth: None, floor };
    spread_fixed_poses(&mut session);
    Ok((session, warnings))
}
