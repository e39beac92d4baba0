//! `docs/session-format.md` is true: its JSON Schema accepts its example and every manifest
//! the writer produces, rejects broken ones, and the example reads. Native only (the
//! validator is a native dev-dependency).
#![cfg(not(target_arch = "wasm32"))]

mod support;

use egoexo_session::capture::{PeopleTrack, View, ViewPeople};
use egoexo_session::format::{read_capture, read_egoexo, write_capture_files, write_egoexo_files};
use egoexo_session::import::{ImportOptions, import_session};
use egoexo_session::placement::{Mount, Placement, Registration, RegistrationRecord, WorldRef};
use serde_json::Value;
use support::*;

/// The fenced block whose info string is exactly `info` (e.g. "json schema").
fn doc_block(info: &str) -> Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/session-format.md");
    let doc = std::fs::read_to_string(&path).unwrap();
    let fence = format!("```{info}\n");
    let start = doc.find(&fence).unwrap_or_else(|| panic!("no ```{info} block in {}", path.display())) + fence.len();
    let end = start + doc[start..].find("\n```").unwrap();
    serde_json::from_str(&doc[start..end]).unwrap_or_else(|e| panic!("```{info} block: {e}"))
}

fn validator() -> jsonschema::Validator {
    jsonschema::validator_for(&doc_block("json schema")).expect("the schema compiles")
}

fn assert_valid(v: &jsonschema::Validator, manifest: &Value, what: &str) {
    let errors: Vec<String> = v.iter_errors(manifest).map(|e| format!("{} at {}", e, e.instance_path())).collect();
    assert!(errors.is_empty(), "{what} fails the schema:\n{}", errors.join("\n"));
}

#[test]
fn the_example_validates_and_reads() {
    let v = validator();
    let example = doc_block("json example");
    assert_valid(&v, &example, "the documented example");
    // With the fixture's data files, the example manifest reads.
    let mut files = egoexo_fixture_files();
    files.insert("session.json".into(), serde_json::to_vec_pretty(&example).unwrap());
    let (session, warnings) = read_egoexo(&tree("example", files)).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    assert_eq!(session.observers.len(), 2);
    assert_eq!(session.ground_truth.unwrap().occlusion[0].observer_id, "observer-1");
}

#[test]
fn written_manifests_validate() {
    let v = validator();
    let nymeria = import_session(&tree("nymeria", nymeria_fixture()), &ImportOptions::default()).unwrap().session;
    // A capture: the Aria fixture's wearer and observers all reconstructed, the first
    // observer's camera also listing people without identity.
    let (mut capture, _) = read_capture(&tree("aria", egoexo_fixture_files())).unwrap();
    for p in &mut capture.participants {
        p.reconstruct = true;
    }
    let ViewPeople::Assigned { keypoints, .. } = &capture.views[0].people else { unreachable!() };
    let people = PeopleTrack {
        timestamps_ns: keypoints.timestamps_ns.clone(),
        frames: keypoints.frames.iter().map(|f| vec![*f, *f]).collect(),
    };
    capture.views.push(View { observer: capture.views[0].observer.clone(), people: ViewPeople::Unassigned(people) });
    let capture_files = write_capture_files(&capture).unwrap();
    let broken_capture = {
        let mut m: Value = serde_json::from_slice(&capture_files["session.json"]).unwrap();
        let last = m["views"].as_array().unwrap().len() - 1;
        m["views"][last]["target"] = "wearer".into();
        m
    };
    assert!(!v.is_valid(&broken_capture), "a view with both a target and people");
    // Placements: a static camera to register, a posed one, an own world with its registration.
    let mut placed = read_egoexo(&tree("aria", egoexo_fixture_files())).unwrap().0;
    placed.observers[0].placement = Placement::fixed_unposed(false);
    placed.observers[0].head.poses.fill(egoexo_core::rigid::RigidTransform::IDENTITY);
    placed.observers[1].placement = Placement {
        world: WorldRef::Own,
        registration: Some(RegistrationRecord {
            result: Registration::as_given(300, 280, 10.0, 9.3, Some(0.6), "checked".into()),
            applied: false,
        }),
        ..Placement::default()
    };
    let mut posed = placed.clone();
    posed.observers[0].placement = Placement { mount: Mount::Fixed, ..Placement::default() };
    for (what, files) in [
        ("placements", write_egoexo_files(&placed).unwrap()),
        ("a posed static camera", write_egoexo_files(&posed).unwrap()),
        ("aria + ground truth", egoexo_fixture_files()),
        ("nymeria", write_egoexo_files(&nymeria).unwrap()),
        ("capture of three participants", capture_files),
    ] {
        let manifest: Value = serde_json::from_slice(&files["session.json"]).unwrap();
        assert_valid(&v, &manifest, what);
    }
}

#[test]
fn the_schema_rejects_broken_manifests() {
    let v = validator();
    let example = doc_block("json example");
    type Edit = Box<dyn Fn(&mut Value)>;
    let broken: Vec<(&str, Edit)> = vec![
        ("version 3", Box::new(|m| m["version"] = 3.into())),
        ("floor without a source", Box::new(|m| m["floor"] = serde_json::json!({"height_m": 0.0}))),
        ("an unknown floor source", Box::new(|m| m["floor"]["source"] = serde_json::json!({"kind": "guess"}))),
        (
            "an unknown hand tracking form",
            Box::new(|m| {
                m["wearer"]["wrist_source"] = serde_json::json!({"kind": "hand_tracking", "file": "x", "form": "v9", "orientation": "from_normals"})
            }),
        ),
        (
            "missing wearer",
            Box::new(|m| {
                m.as_object_mut().unwrap().remove("wearer");
            }),
        ),
        ("path with ..", Box::new(|m| m["wearer"]["head"] = "../x.csv".into())),
        ("absolute path", Box::new(|m| m["observers"][0]["trajectory"] = "/x.csv".into())),
        (
            "fisheye with 4 params",
            Box::new(|m| m["observers"][0]["camera"]["params"] = serde_json::json!([1, 2, 3, 4])),
        ),
        ("observer id with a space", Box::new(|m| m["observers"][0]["id"] = "a b".into())),
        ("unknown field", Box::new(|m| m["extra"] = 1.into())),
        ("z-up world", Box::new(|m| m["conventions"]["world"] = "z_up".into())),
        ("stature in cm", Box::new(|m| m["subject"]["height_m"] = 170.into())),
    ];
    for (what, edit) in broken {
        let mut m = example.clone();
        edit(&mut m);
        assert!(!v.is_valid(&m), "the schema accepts a manifest with {what}");
    }
}
