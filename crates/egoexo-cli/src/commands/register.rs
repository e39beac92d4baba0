//! `egoexo register <session>`: check or register every observer's world against the wearer's
//! (a capture's participants into the anchor's) and report it — one JSON object with
//! `--json` — optionally writing the registered session; and the `--register` choice the
//! reconstruction shares (docs/registration.md).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_infer::Engine;
use egoexo_infer::plan::resolve_tracking;
use egoexo_register::capture::{CaptureRegistration, register_capture};
use egoexo_register::{Outcome, RegisterMode, RegisterSettings, SessionRegistration, register_session};
use egoexo_session::align::{AlignOptions, align};
use egoexo_session::capture::Capture;
use egoexo_session::format::{save_capture, save_egoexo};
use egoexo_session::placement::Registration;
use serde_json::{Value, json};

use super::models::{load_model_set, models_dir, read_manifest};
use super::session_input::SessionInput;
use super::tracking::TrackingArg;

/// `--register`: what to do with observers' worlds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum RegisterArg {
    /// Keep worlds given as shared whose views agree; register the others.
    Auto,
    /// Keep every world as given (observers in a world of their own are left out).
    Off,
    /// Register every observer.
    Force,
}

impl From<RegisterArg> for RegisterMode {
    fn from(arg: RegisterArg) -> Self {
        match arg {
            RegisterArg::Auto => RegisterMode::Auto,
            RegisterArg::Off => RegisterMode::Off,
            RegisterArg::Force => RegisterMode::Force,
        }
    }
}

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub input: SessionInput,
    /// `auto`: check worlds given as shared and register the others; `force`: register every
    /// observer; `off`: only report what the placements say.
    #[arg(long, value_enum, default_value_t = RegisterArg::Auto)]
    pub mode: RegisterArg,
    /// In a capture of several participants: whose world the others are registered into
    /// [default: the first participant's].
    #[arg(long, value_name = "ID")]
    pub anchor: Option<String>,
    /// Print one JSON object: `{"observers": [...], "pairs": [...]}`.
    #[arg(long)]
    pub json: bool,
    /// Write the registered session (or capture) as `.egoexo` here (a folder when the path
    /// has no `.egoexo` extension).
    #[arg(short = 'o', long = "output")]
    pub output: Option<PathBuf>,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
    /// Models folder [default: ./models, else the repository's models/].
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Wearer tracking for the coarse body [default: as the devices allow].
    #[arg(long, value_enum)]
    pub tracking: Option<TrackingArg>,
}

pub fn run(args: Args) -> Result<()> {
    if let Some(output) = &args.output
        && output.exists()
        && !args.force
    {
        bail!("{} exists; pass --force to replace it", output.display());
    }
    let settings = RegisterSettings { mode: args.mode.into(), ..RegisterSettings::default() };
    let tracking = args.tracking.map(TrackingMode::from);
    let dir = models_dir(args.models.as_deref());
    if let Some(imported) = args.input.import_several()? {
        for warning in &imported.warnings {
            eprintln!("warning: {warning}");
        }
        let mut capture = imported.capture;
        let anchor = anchor_index(&capture, args.anchor.as_deref())?;
        let engine = engine_for(&dir, &[TrackingMode::OnePoint, TrackingMode::ThreePoint])?;
        let report = register_capture(Some(&engine), tracking, &mut capture, anchor, &settings)?;
        if args.json {
            println!("{}", serde_json::to_string_pretty(&capture_json(&report))?);
        } else {
            print_capture(&report);
        }
        if let Some(output) = &args.output {
            save_capture(&capture, Default::default(), output, !is_egoexo_file(output))
                .with_context(|| format!("cannot write {}", output.display()))?;
            eprintln!("wrote {}", output.display());
        }
        return Ok(());
    }
    if args.anchor.is_some() {
        bail!("--anchor names a participant of a capture; {} is one session", args.input.session.display());
    }
    let mut imported = args.input.import()?;
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    let aligned = align(&imported.session, &AlignOptions::default())?;
    let tracking = resolve_tracking(&aligned, tracking)?;
    let engine = engine_for(&dir, &[tracking])?;
    let report = register_session(Some(&engine), tracking, &mut imported.session, &settings)?;
    if args.json {
        println!("{}", serde_json::to_string_pretty(&session_json(&report))?);
    } else {
        print_session(&report);
    }
    if let Some(output) = &args.output {
        save_egoexo(&imported.session, output, !is_egoexo_file(output))
            .with_context(|| format!("cannot write {}", output.display()))?;
        eprintln!("wrote {}", output.display());
    }
    Ok(())
}

fn is_egoexo_file(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("egoexo"))
}

/// The index of participant `anchor` (the first without one).
pub fn anchor_index(capture: &Capture, anchor: Option<&str>) -> Result<usize> {
    match anchor {
        None => Ok(0),
        Some(id) => capture.participants.iter().position(|p| p.id == id).with_context(|| {
            let ids: Vec<&str> = capture.participants.iter().map(|p| p.id.as_str()).collect();
            format!("--anchor {id}: the capture's participants are {}", ids.join(", "))
        }),
    }
}

/// An engine with the models of every tracking mode in `modes` the models folder has.
pub fn engine_for(dir: &Path, modes: &[TrackingMode]) -> Result<Engine> {
    let manifest = read_manifest(dir)?;
    let mut engine = Engine::new();
    for &tracking in modes {
        if let Some(set) = load_model_set(dir, &manifest, tracking)? {
            engine = engine.with_models(set);
        }
    }
    Ok(engine)
}

/// One entry of `register --json`: the transform that maps the observer's world into the
/// session's (`p_session = R_y(yaw_deg) · p_observer + translation_m`), its 1σ and the frames
/// used. Nothing solved: `as-given` with the identity (or the placement's verdict).
fn entry_json(id: &str, outcome: Option<Outcome>, registration: Option<&Registration>, message: &str) -> Value {
    let status = registration
        .map_or(if outcome == Some(Outcome::LeftOut) { "not-registered" } else { "as-given" }, |r| r.status.name());
    let mut entry = json!({
        "id": id,
        "status": status,
        "yaw_deg": registration.map_or(0.0, |r| r.yaw_deg),
        "translation_m": registration.map_or([0.0; 3], Registration::translation_m),
        "sigma_yaw_deg": registration.and_then(|r| r.sigma_yaw_deg),
        "sigma_translation_m": registration.and_then(|r| r.sigma_translation_m),
        "frames": registration.map_or(0, |r| r.frames),
        "inlier_frames": registration.map_or(0, |r| r.inlier_frames),
        "view_s": registration.map_or(0.0, |r| r.view_s),
        "message": message,
    });
    if let Some(outcome) = outcome {
        entry["fused"] = json!(outcome != Outcome::LeftOut);
    }
    if let Some(r) = registration {
        entry["dof"] = json!(r.dof.count());
        entry["clock_offset_s"] = json!(r.clock_offset_s);
        if let Some(s) = r.sigma_clock_offset_s {
            entry["sigma_clock_offset_s"] = json!(s);
        }
        if let Some(f) = r.focal_px {
            entry["focal_px"] = json!(f);
        }
        if let Some(r) = r.sigma_rotation_deg {
            entry["sigma_rotation_deg"] = json!(r);
        }
    }
    entry
}

/// `register --json` of a session.
pub fn session_json(report: &SessionRegistration) -> Value {
    let observers: Vec<Value> = report
        .observers
        .iter()
        .map(|o| entry_json(&o.id, Some(o.outcome), o.registration.as_ref(), &o.message))
        .collect();
    json!({"mode": report.mode.name(), "observers": observers, "pairs": [], "coarse_windows": report.coarse_windows})
}

/// `register --json` of a capture: per participant other than the anchor, and per pair of a
/// camera and a participant of another world it sees.
pub fn capture_json(report: &CaptureRegistration) -> Value {
    let observers: Vec<Value> = report
        .participants
        .iter()
        .map(|p| entry_json(&p.id, Some(p.outcome), p.registration.as_ref(), &p.message))
        .collect();
    let pairs: Vec<Value> = report
        .pairs
        .iter()
        .map(|pair| {
            let mut entry = entry_json(&pair.observer, None, Some(&pair.registration), &pair.registration.reason);
            entry["observer"] = json!(pair.observer);
            entry["target"] = json!(pair.target);
            entry
        })
        .collect();
    json!({
        "mode": report.mode.name(),
        "anchor": report.anchor,
        "observers": observers,
        "pairs": pairs,
        "coarse_windows": report.coarse_windows,
    })
}

/// The session's registration step in lines: `note:` for worlds kept or registered,
/// `warning:` for observers left out.
pub fn print_session(report: &SessionRegistration) {
    for o in &report.observers {
        print_line(&o.id, o.outcome, &o.message);
    }
}

/// The capture's registration step in lines.
pub fn print_capture(report: &CaptureRegistration) {
    for p in &report.participants {
        print_line(&p.id, p.outcome, &p.message);
    }
}

fn print_line(id: &str, outcome: Outcome, message: &str) {
    match outcome {
        Outcome::Kept => eprintln!("note: {id}: {message}"),
        Outcome::Registered => eprintln!("warning: {id}: {message}"),
        Outcome::LeftOut => eprintln!("warning: {id}: {message}"),
    }
}
