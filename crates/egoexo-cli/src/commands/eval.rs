//! `egoexo eval`: the paper's metric table on simulated sessions of chosen subjects.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_core::TrackingMode;
use egoexo_dataset::eval::{
    EvalOptions, LIVE_LOOKAHEADS, evaluate, evaluate_live, format_live_table, format_table, nearest_neighbour_index,
};
use egoexo_dataset::registration::{
    DetectorCondition, RegistrationEvalOptions, VISIBILITY_S, evaluate_registration, format_registration_table,
};
use egoexo_dataset::shards::WristKind;
use egoexo_infer::{Engine, Method};
use indicatif::{ProgressBar, ProgressStyle};

use super::models::{load_all_models, load_model_set, read_manifest};
use super::simulation::SimulationArgs;

#[derive(clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub simulation: SimulationArgs,
    /// Models folder: adds the `ego-only`, `ego-exo` and `ego-exo-ungated` rows.
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Score the networks without the floor constraint (feet the networks put through the
    /// floor stay there): the "before" of the feet table.
    #[arg(long)]
    pub no_floor_contact: bool,
    /// Only the clips where the head drops at least this far (metres) below the subject's
    /// standing head height: crouching, kneeling, sitting.
    #[arg(long, value_name = "METRES")]
    pub head_drop: Option<f32>,
    /// The live table instead: ego-only and ego-exo read out each lookahead before their
    /// window's end, as the page reconstructs live, against the offline result (needs --models);
    /// by the offline networks and, where the manifest ships one, the live variant trained for
    /// that lookahead.
    #[arg(long)]
    pub live: bool,
    /// Lookaheads of the live table, frames.
    #[arg(long, value_delimiter = ',', default_values_t = LIVE_LOOKAHEADS)]
    pub lookaheads: Vec<usize>,
    /// The registration tables instead (docs/registration.md; needs --models): every
    /// observer moved into a world of its own, registered with only its first `--visibility`
    /// seconds of views under each `--detector` condition, against the truth; and the MPJPE of
    /// ego-exo with the true, the registered and the moved worlds.
    #[arg(long)]
    pub perturb_worlds: bool,
    /// Seconds of mutual visibility of the registration table.
    #[arg(long, value_delimiter = ',', default_values_t = VISIBILITY_S, requires = "perturb_worlds")]
    pub visibility: Vec<f64>,
    /// Detector conditions of the registration table: clean, simulator, harsh.
    #[arg(long, value_delimiter = ',', value_parser = parse_condition, default_value = "clean,simulator,harsh", requires = "perturb_worlds")]
    pub detector: Vec<DetectorCondition>,
    /// With --perturb-worlds: the observers are static cameras (on tripods, aimed at the middle
    /// of the wearer's path) that know nothing of their pose: each is registered in 6 DoF (its
    /// pose in the wearer's world). No MPJPE table.
    #[arg(long, requires = "perturb_worlds")]
    pub static_cameras: bool,
}

fn parse_condition(s: &str) -> Result<DetectorCondition, String> {
    DetectorCondition::ALL
        .into_iter()
        .find(|c| c.name() == s)
        .ok_or_else(|| format!("`{s}`: expected clean, simulator or harsh"))
}

pub fn run(args: Args) -> Result<()> {
    let sim = &args.simulation;
    let library = sim.open_library()?;
    let tracking = sim.tracking_mode();
    let bar = if args.json { ProgressBar::hidden() } else { ProgressBar::new(0) };
    bar.set_style(
        ProgressStyle::with_template("eval {bar:40} {pos}/{len} clips [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let mut progress = |done: usize, total: usize| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    };
    if args.perturb_worlds {
        return run_registration(&args, &library, &mut progress, &bar);
    }
    if args.live {
        let Some(dir) = &args.models else {
            bail!("--live compares the networks' live and offline results: pass --models DIR");
        };
        let models = load_all_models(dir, &read_manifest(dir)?)?;
        if models.offline().models(tracking).is_none() {
            bail!("{} has no {}-point models", dir.display(), tracking.points());
        }
        let options = eval_options(&args, vec![Method::EgoOnly, Method::EgoExo]);
        let report = evaluate_live(&library, &models, &options, &args.lookaheads, &mut progress)?;
        bar.finish_and_clear();
        if args.json {
            println!("{}", serde_json::to_string(&report)?);
        } else {
            print!("{}", format_live_table(&report));
        }
        return Ok(());
    }
    let training: Vec<u32> = library.subjects().into_iter().filter(|s| !sim.subjects.contains(s)).collect();
    if training.is_empty() {
        bail!("every subject of the library is being evaluated; the nearest-neighbour baseline needs other subjects");
    }
    // Hand-tracking wrists: a clip whose hands never came into view has no wrists and is
    // reconstructed 1-point, as a real session would be; so both modes are loaded.
    let modes = match sim.wrists() {
        WristKind::HandTracking | WristKind::Mixed => vec![tracking, TrackingMode::OnePoint],
        WristKind::Devices => vec![tracking],
    };
    let mut engine = Engine::new();
    for &mode in &modes {
        engine = engine.with_nearest_neighbour(mode, nearest_neighbour_index(&library, &training, mode, sim.seed, 2)?);
    }
    let mut methods = vec![Method::RestPose, Method::NearestNeighbour];
    if let Some(dir) = &args.models {
        let manifest = read_manifest(dir)?;
        for &mode in &modes {
            let set = load_model_set(dir, &manifest, mode)?
                .with_context(|| format!("{} has no {}-point models", dir.display(), mode.points()))?;
            engine = engine.with_models(set);
        }
        methods.extend([Method::EgoOnly, Method::EgoExo, Method::EgoExoUngated]);
    }
    let options = eval_options(&args, methods);
    let report = evaluate(&library, &engine, &options, &mut progress)?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", format_table(&report));
        if args.models.is_none() {
            println!("\n(baselines only: pass --models DIR for the networks' rows)");
        }
    }
    Ok(())
}

/// `--perturb-worlds`: the registration tables.
fn run_registration(
    args: &Args,
    library: &egoexo_mocap::MotionLibrary,
    progress: &mut dyn FnMut(usize, usize),
    bar: &ProgressBar,
) -> Result<()> {
    let sim = &args.simulation;
    let Some(dir) = &args.models else {
        bail!("--perturb-worlds registers with the coarse body and reconstructs: pass --models DIR");
    };
    let tracking = sim.tracking_mode();
    let manifest = read_manifest(dir)?;
    let set = load_model_set(dir, &manifest, tracking)?
        .with_context(|| format!("{} has no {}-point models", dir.display(), tracking.points()))?;
    let engine = Engine::new().with_models(set);
    let options = RegistrationEvalOptions {
        subjects: sim.subjects.clone(),
        observers: sim.observers.max(1),
        tracking,
        seed: sim.seed,
        visibility_s: args.visibility.clone(),
        conditions: args.detector.clone(),
        mpjpe: !args.static_cameras,
        static_cameras: args.static_cameras,
    };
    let started = std::time::Instant::now();
    let mut clock = move || started.elapsed().as_secs_f64() * 1e3;
    let report = evaluate_registration(library, &engine, &options, &mut clock, progress)?;
    bar.finish_and_clear();
    if args.json {
        println!("{}", serde_json::to_string(&report)?);
    } else {
        print!("{}", format_registration_table(&report));
    }
    Ok(())
}

/// What `args` ask to evaluate, with `methods`.
fn eval_options(args: &Args, methods: Vec<Method>) -> EvalOptions {
    let sim = &args.simulation;
    EvalOptions {
        subjects: sim.subjects.clone(),
        observers: sim.observers,
        tracking: sim.tracking_mode(),
        wrists: sim.wrists(),
        floor_contact: !args.no_floor_contact,
        min_head_drop_m: args.head_drop,
        seed: sim.seed,
        methods,
    }
}
