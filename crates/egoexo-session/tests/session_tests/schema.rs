//! `docs/session-format.md` is true: its JSON Schema accepts its example and every manifest
//! the writer produces, rejects broken ones, and the example reads. The schema is checked by
//! an independent validator, Python's `jsonschema` (draft 2020-12) in the test venv, so the
//! test neither trusts the Rust reader's idea of the format nor compiles a validator crate.
//! Native only (it runs a process).
#![cfg(not(target_arch = "wasm32"))]

use std::process::Command;

use crate::support::*;
use egoexo_session::capture::{PeopleTrack, View, ViewPeople};
use egoexo_session::format::{read_capture, read_egoexo, write_capture_files, write_egoexo_files};
use egoexo_session::import::{ImportOptions, import_session};
use egoexo_session::placement::{Mount, Placement, Registration, RegistrationRecord, WorldRef};
use egoexo_test_support::{python, run_tool};
use serde_json::Value;

/// The fenced block whose info string is exactly `info` (e.g. "json schema").
fn doc_block(info: &str) -> Value {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../docs/session-format.md");
    let doc = std::fs::read_to_string(&path).unwrap();
    let fence = format!("```{info}\n");
    let start = doc.find(&fence).unwrap_or_else(|| panic!("no ```{info} block in {}", path.display())) + fence.len();
    let end = start + doc[start..].find("\n```").unwrap();
    serde_json::from_str(&doc[start..end]).unwrap_or_else(|e| panic!("```{info} block: {e}"))
}

/// Checks the schema itself (a `SchemaError` fails the test), then validates each manifest;
/// prints a JSON list with each one's errors (`message at /instance/path`).
const VALIDATE_PY: &str = r#"
import json, sys
from jsonschema import Draft202012Validator
job = json.load(open(sys.argv[1]))
Draft202012Validator.check_schema(job["schema"])
validator = Draft202012Validator(job["schema"])
print(json.dumps([
    [f"{e.message} at /{'/'.join(map(str, e.absolute_path))}" for e in validator.iter_errors(m)]
    for m in job["manifests"]
]))
"#;

/// Each manifest's schema errors (none for a valid one), in order, from one validator run.
fn schema_errors(name: &str, manifests: &[Value]) -> Vec<Vec<String>> {
    let job = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("schema-{name}.json"));
    let body = serde_json::json!({"schema": doc_block("json schema"), "manifests": manifests});
    std::fs::write(&job, serde_json::to_vec(&body).unwrap()).unwrap();
    let out = run_tool(Command::new(python()).arg("-c").arg(VALIDATE_PY).arg(&job));
    let errors: Vec<Vec<String>> =
        serde_json::from_str(&out).unwrap_or_else(|e| panic!("validator output {out:?}: {e}"));
    assert_eq!(errors.len(), manifests.len(), "one verdict per manifest");
    errors
}

fn assert_valid(errors: &[String], what: &str) {
    assert!(errors.is_empty(), "{what} fails the schema:\n{}", errors.join("\n"));
}

#[test]
fn the_example_validates_and_reads() {
    let example = doc_block("json example");
    assert_valid(&schema_errors("example", std::slice::from_ref(&example))[0], "the documented example");
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
    let written = [
        ("placements", write_egoexo_files(&placed).unwrap()),
        ("a posed static camera", write_egoexo_files(&posed).unwrap()),
        ("aria + ground truth", egoexo_fixture_files()),
        ("nymeria", write_egoexo_files(&nymeria).unwrap()),
        ("capture of three participants", capture_files),
    ];
    let mut manifests: Vec<Value> =
        written.iter().map(|(_, files)| serde_json::from_slice(&files["session.json"]).unwrap()).collect();
    manifests.push(broken_capture);
    let errors = schema_errors("written", &manifests);
    for ((what, _), errors) in written.iter().zip(&errors) {
        assert_valid(errors, what);
    }
    assert!(!errors.last().unwrap().is_empty(), "the schema accepts a view with both a target and people");
}

#[test]
fn the_schema_rejects_broken_manifests() {
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
    let manifests: Vec<Value> = broken
        .iter()
        .map(|(_, edit)| {
            let mut m = example.clone();
            edit(&mut m);
            m
        })
        .collect();
    for ((what, _), errors) in broken.iter().zip(schema_errors("broken", &manifests)) {
        assert!(!errors.is_empty(), "the schema accepts a manifest with {what}");
    }
}
