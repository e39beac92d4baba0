//! Property: writing any valid session as `.egoexo` (zip or folder) and reading it back gives
//! the same session, bit for bit.

use crate::support;

use egoexo_core::camera::{CameraCalibration, Fisheye624, Pinhole, Projection};
use egoexo_core::exo_keypoints::Keypoint2d;
use egoexo_core::glam::{Quat, Vec2, Vec3};
use egoexo_core::motion::SmplMotion;
use egoexo_core::rigid::RigidTransform;
use egoexo_core::skeleton::{SmplPose, SmplSkeleton};
use egoexo_session::capture::{Capture, PeopleTrack, View, ViewPeople};
use egoexo_session::format::{read_capture, read_egoexo, write_capture_files, write_egoexo_files, write_egoexo_zip};
use egoexo_session::import::{ImportOptions, import_session};
use egoexo_session::model::*;
use egoexo_session::placement::{ClockRef, Mount, Placement, Registration, RegistrationRecord, WorldRef};
use egoexo_session::{FileTree, Limits};
use proptest::prelude::*;

fn quat() -> impl Strategy<Value = Quat> {
    (-1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0, -1.0f32..1.0)
        .prop_filter("non-degenerate", |(x, y, z, w)| x * x + y * y + z * z + w * w > 0.01)
        .prop_map(|(x, y, z, w)| Quat::from_xyzw(x, y, z, w).normalize())
}

fn pose() -> impl Strategy<Value = RigidTransform> {
    (quat(), -50.0f32..50.0, -5.0f32..5.0, -50.0f32..50.0)
        .prop_map(|(q, x, y, z)| RigidTransform { rotation: q, translation: Vec3::new(x, y, z) })
}

/// Strictly increasing timestamps: the first within 10 ms after `start`, then steps of
/// 10–50 ms (so every stream of ≥ 2 samples overlaps every other: one clock).
fn timestamps(n: std::ops::Range<usize>, start: i64) -> impl Strategy<Value = Vec<i64>> {
    (prop::collection::vec(10_000_000i64..50_000_000, n), 0i64..10_000_000).prop_map(move |(deltas, offset)| {
        let mut t = start + offset;
        deltas
            .iter()
            .enumerate()
            .map(|(i, d)| {
                if i > 0 {
                    t += d;
                }
                t
            })
            .collect()
    })
}

fn trajectory(start: i64) -> impl Strategy<Value = Trajectory> {
    timestamps(2..30, start).prop_flat_map(|ts| {
        let n = ts.len();
        (Just(ts), prop::collection::vec(pose(), n))
            .prop_map(|(timestamps_ns, poses)| Trajectory { timestamps_ns, poses })
    })
}

fn camera() -> impl Strategy<Value = CameraCalibration> {
    let projection = prop_oneof![
        (300.0f32..900.0, 200.0f32..800.0).prop_map(|(f, c)| {
            let mut p = support::RGB_PARAMS;
            p[0] = f;
            p[1] = c;
            Projection::Fisheye624(Fisheye624::new(p).unwrap())
        }),
        (100.0f32..2000.0, 100.0f32..2000.0, 0.0f32..1000.0, 0.0f32..1000.0)
            .prop_map(|(fx, fy, cx, cy)| Projection::Pinhole(Pinhole::new(fx, fy, cx, cy).unwrap())),
    ];
    (projection, 1u32..4000, 1u32..4000, pose(), prop::option::of(10.0f32..2000.0)).prop_map(|(p, w, h, t, r)| {
        let c = CameraCalibration::new(p, w, h, t).unwrap();
        match r {
            Some(r) => c.with_valid_radius(r),
            None => c,
        }
    })
}

fn keypoints(start: i64) -> impl Strategy<Value = KeypointTrack> {
    timestamps(2..20, start).prop_flat_map(|ts| {
        let n = ts.len();
        let kp = prop::option::of((-100.0f32..2000.0, -100.0f32..2000.0, 0.0f32..=1.0))
            .prop_map(|o| o.map(|(x, y, s)| Keypoint2d { pixel: Vec2::new(x, y), score: s }));
        (Just(ts), prop::collection::vec(prop::array::uniform17(kp), n))
            .prop_map(|(timestamps_ns, frames)| KeypointTrack { timestamps_ns, frames })
    })
}

fn context(start: i64) -> impl Strategy<Value = ContextFeatureTrack> {
    (timestamps(1..6, start), 1usize..8).prop_flat_map(|(ts, dim)| {
        let n = ts.len();
        (Just(ts), Just(dim), prop::collection::vec(-10.0f32..10.0, n * dim))
            .prop_map(|(timestamps_ns, dim, values)| ContextFeatureTrack { timestamps_ns, dim, values })
    })
}

const START: i64 = 1_000_000_000;

/// A worn device's placement: any world, gravity, clock and focal knowledge, sometimes with a
/// registration record (static cameras: `format`'s own tests).
fn placement() -> impl Strategy<Value = Placement> {
    (any::<[bool; 5]>(), -180.0f64..180.0).prop_map(|([own, gravity, own_clock, focal_known, recorded], yaw)| {
        Placement {
            world: if own { WorldRef::Own } else { WorldRef::Shared },
            gravity,
            clock: if own_clock { ClockRef::Own } else { ClockRef::Shared },
            mount: Mount::Worn,
            focal_known,
            registration: recorded.then(|| RegistrationRecord {
                result: Registration {
                    yaw_deg: yaw,
                    sigma_yaw_deg: Some(0.5),
                    ..Registration::as_given(120, 100, 4.0, 3.3, Some(0.7), "checked".into())
                },
                applied: own,
            }),
        }
    })
}

fn observer(index: usize) -> impl Strategy<Value = Observer> {
    (
        trajectory(START),
        camera(),
        prop::option::of(keypoints(START)),
        prop::option::of(context(START)),
        any::<bool>(),
        placement(),
    )
        .prop_map(move |(head, camera, keypoints, context_features, video, placement)| Observer {
            id: format!("obs-{index}"),
            head,
            camera,
            keypoints,
            // Every other observer's video with its frame times (the Aria folders' capture times).
            video: video.then(|| VideoRef {
                path: format!("videos/obs-{index}.mp4"),
                start_ns: START + 5,
                frame_times_ns: if index % 2 == 1 { vec![START + 5, START + 38, START + 72] } else { Vec::new() },
            }),
            context_features,
            placement,
        })
}

fn smpl_pose() -> impl Strategy<Value = SmplPose> {
    (quat(), prop::array::uniform21(quat()), -5.0f32..5.0, 0.0f32..2.0, -5.0f32..5.0)
        .prop_map(|(r, body, x, y, z)| SmplPose { root_orientation: r, body, translation: Vec3::new(x, y, z) })
}

fn session() -> impl Strategy<Value = Session> {
    let observers = (0usize..3).prop_flat_map(|n| (0..n).map(observer).collect::<Vec<_>>());
    let wrists = prop::option::of((trajectory(START), trajectory(START)));
    let subject =
        (prop::option::of(1.0f32..2.2), prop::option::of(prop::collection::vec(-3.0f32..3.0, 1..16)), any::<bool>())
            .prop_map(|(height_m, betas, joints)| SubjectInfo {
                height_m,
                betas,
                rest_joints: joints.then(|| SmplSkeleton::mean_shape().scaled(1.05).rest_joints().to_owned()),
            });
    let gt = prop::option::of((prop::collection::vec(smpl_pose(), 1..12), 10.0f32..120.0, any::<u16>()));
    let floor = prop::option::of((-3.0f32..3.0, 0u8..3, 1u64..100_000, 1.4f32..2.0));
    (trajectory(START), wrists, observers, subject, gt, "[a-z][a-z0-9_-]{0,12}", floor, any::<bool>()).prop_map(
        |(head, wrists, observers, subject, gt, name, floor, hand_tracked)| {
            let floor = floor.map(|(height_m, kind, points, stature_m)| Floor {
                height_m,
                source: match kind {
                    0 => FloorSource::SemidensePoints { file: "wearer/slam/global_points.csv.gz".into(), points },
                    1 => FloorSource::StandingHead {
                        standing_head_m: height_m + 1.6,
                        stature_m,
                        stature_known: points % 2 == 0,
                    },
                    _ => FloorSource::GroundTruth,
                },
            });
            let ground_truth = gt.map(|(poses, fps, mask)| {
                let n = poses.len();
                let motion =
                    SmplMotion::new(fps, START + 10_000_000, SmplSkeleton::mean_shape(), Some(vec![0.5, -0.25]), poses)
                        .unwrap();
                let occlusion = observers
                    .iter()
                    .take(1)
                    .map(|o| ObserverOcclusion { observer_id: o.id.clone(), occluded: vec![mask & 0x1fff; n] })
                    .collect();
                GroundTruth { motion, occlusion }
            });
            let (left_wrist, right_wrist) = match wrists {
                Some((l, r)) => (Some(l), Some(r)),
                None => (None, None),
            };
            let wrist_source = if hand_tracked && left_wrist.is_some() {
                WristSource::HandTracking {
                    file: "wearer/hand_tracking/wrist_and_palm_poses.csv".into(),
                    form: HandTrackingForm::WristAndPalmV2,
                    orientation: WristOrientation::FromNormals,
                }
            } else {
                WristSource::Devices
            };
            Session {
                name,
                wearer: Wearer {
                    head,
                    left_wrist,
                    right_wrist,
                    wrist_source,
                    head_joint_in_device: Vec3::new(0.01, -0.06, -0.09),
                },
                observers,
                subject,
                ground_truth,
                floor,
            }
        },
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    #[test]
    fn write_then_read_is_the_identity(s in session()) {
        let zip = write_egoexo_zip(&s).unwrap();
        let imported = import_session(&FileTree::from_zip("s.egoexo", zip, Limits::default()).unwrap(), &ImportOptions::default()).unwrap();
        prop_assert_eq!(&imported.session, &s);
        let (from_folder, warnings) = read_egoexo(&support::tree("s", write_egoexo_files(&s).unwrap())).unwrap();
        prop_assert_eq!(&from_folder, &s);
        // The writer writes only keys the reader knows (one typed manifest: format/manifest.rs).
        prop_assert!(!warnings.iter().any(|w| w.message.contains("unknown field")), "{:?}", warnings);
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Any session as a capture in which everyone is reconstructed and the first observer's
    /// camera also reports everyone it saw without identity (each frame of its keypoints
    /// `people` times, some frames with nobody): version 3 round-trips exactly.
    #[test]
    fn a_capture_of_several_participants_round_trips(s in session(), people in 0usize..3) {
        let mut capture = Capture::from_session(&s);
        for p in &mut capture.participants {
            p.reconstruct = true;
        }
        if let Some(kp) = s.observers.iter().find_map(|o| o.keypoints.as_ref().map(|k| (o.id.clone(), k))) {
            let (id, track) = kp;
            let frames = track.frames.iter().enumerate().map(|(i, f)| vec![*f; (people + i) % 3]).collect();
            capture.views.push(View {
                observer: id,
                people: ViewPeople::Unassigned(PeopleTrack { timestamps_ns: track.timestamps_ns.clone(), frames }),
            });
        }
        let files = write_capture_files(&capture).unwrap();
        let manifest: serde_json::Value = serde_json::from_slice(&files["session.json"]).unwrap();
        prop_assert_eq!(manifest["version"].as_u64(), Some(3));
        let (back, warnings) = read_capture(&support::tree("c", files.clone())).unwrap();
        prop_assert_eq!(&back, &capture);
        prop_assert!(!warnings.iter().any(|w| w.message.contains("unknown field")), "{:?}", warnings);
        // Several participants to reconstruct: not one session.
        if capture.participants.len() > 1 {
            let error = read_egoexo(&support::tree("c", files)).unwrap_err().to_string();
            prop_assert!(error.contains("participants to reconstruct"), "{}", error);
        }
    }

    /// A one-wearer file (version 2) reads as a capture of one wearer and observers that are
    /// not reconstructed; written as version 3 it still reads as the same session.
    #[test]
    fn a_session_is_a_capture_of_one_wearer(s in session()) {
        let (capture, _) = read_capture(&support::tree("s", write_egoexo_files(&s).unwrap())).unwrap();
        prop_assert_eq!(&capture, &Capture::from_session(&s));
        prop_assert_eq!(capture.reconstructed().count(), 1);
        let (again, _) = read_egoexo(&support::tree("c", write_capture_files(&capture).unwrap())).unwrap();
        prop_assert_eq!(&again, &s);
    }
}
