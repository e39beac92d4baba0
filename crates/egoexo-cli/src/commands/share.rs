//! `egoexo share <session> --server URL`: reconstruct a session as the page does, seal it in a
//! share and upload it (the same container and envelope as the page's Share button; the key
//! stays in the printed link). The input may also be a reconstruction already shared: a
//! folder written by `share get`, re-shared as it is. `egoexo share get <link> -o DIR`:
//! download, open and unpack a share, with the motion in every export format. `egoexo share
//! delete <link> --token T`: delete it before it expires, with the token `share` printed.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use egoexo_protocol::share::{ApiError, CreatedShare, Expiry};
use egoexo_protocol::worker::ExportFormat;
use egoexo_share::ShareLink;
use egoexo_share::{container, envelope};
use egoexo_web_worker::SessionWorker;
use indicatif::{ProgressBar, ProgressStyle};

use super::models::models_dir;
use super::session_input::ImportArgs;

/// What made a share, in its manifest.
const CREATED_BY: &str = concat!("egoexo ", env!("CARGO_PKG_VERSION"), " (CLI)");

#[derive(clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct Args {
    #[command(subcommand)]
    pub command: Option<ShareCommand>,
    /// The session to reconstruct and share (a `.egoexo`, an Aria MPS folder, a Nymeria
    /// sequence, or a zip of any of them), or a reconstruction to share again (a folder
    /// written by `egoexo share get`).
    #[arg(required = true)]
    pub session: Option<PathBuf>,
    #[command(flatten)]
    pub create: CreateArgs,
}

#[derive(clap::Subcommand)]
pub enum ShareCommand {
    /// Download a share by its link, decrypt it and write its files into a folder.
    Get(GetArgs),
    /// Delete a share before it expires, with the delete token printed when it was made.
    Delete(DeleteArgs),
}

#[derive(clap::Args)]
pub struct CreateArgs {
    #[command(flatten)]
    pub import: ImportArgs,
    /// The egoexo server (`https://host/`): the link opens its page.
    #[arg(long, required = true)]
    pub server: Option<String>,
    /// How long the share lives: 1h, 1d or 30d.
    #[arg(long, default_value = "1d", value_parser = parse_expiry)]
    pub expires: Expiry,
    /// Leave the recording out (the collaborator can view and export, not re-run).
    #[arg(long)]
    pub no_recording: bool,
    /// Models folder [default: ./models, else the repository's models/].
    #[arg(long)]
    pub models: Option<PathBuf>,
}

#[derive(clap::Args)]
pub struct GetArgs {
    /// The share link (`https://host/#share=<id>.<key>`).
    pub link: String,
    /// The folder to write into (created if missing).
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// The API's server, when it is not the page's own origin.
    #[arg(long)]
    pub server: Option<String>,
    /// Replace files that exist.
    #[arg(long)]
    pub force: bool,
}

#[derive(clap::Args)]
pub struct DeleteArgs {
    /// The share link (`https://host/#share=<id>.<key>`).
    pub link: String,
    /// The delete token `egoexo share` printed (the page keeps its own in the browser).
    #[arg(long)]
    pub token: String,
    /// The API's server, when it is not the page's own origin.
    #[arg(long)]
    pub server: Option<String>,
}

fn parse_expiry(text: &str) -> Result<Expiry, String> {
    Expiry::parse(text)
}

fn agent() -> ureq::Agent {
    ureq::Agent::config_builder().http_status_as_error(false).build().into()
}

/// The API's error message of a failed answer, or its status.
fn api_failure(what: &str, status: u16, body: &[u8]) -> anyhow::Error {
    match serde_json::from_slice::<ApiError>(body) {
        Ok(e) => anyhow::anyhow!("{what}: {} (HTTP {status}, {:?})", e.error.message, e.error.kind),
        Err(_) => anyhow::anyhow!("{what}: HTTP {status} {}", String::from_utf8_lossy(&body[..body.len().min(200)])),
    }
}

pub fn run(args: Args) -> Result<()> {
    match args.command {
        Some(ShareCommand::Get(get)) => run_get(get),
        Some(ShareCommand::Delete(delete)) => run_delete(delete),
        None => run_create(args.session.context("a session to share is required")?, args.create),
    }
}

fn run_create(session: PathBuf, args: CreateArgs) -> Result<()> {
    let server = args.server.clone().context("--server is required")?;
    let page = format!("{}/", server.trim_end_matches('/'));
    let (container, what) = if session.join(container::MANIFEST_FILE).is_file() {
        reshare(&session, !args.no_recording)?
    } else {
        reconstruct_and_pack(&session, &args)?
    };
    let key = egoexo_share::link::random_key()?;
    let sealed = envelope::seal(&key, &envelope::random_iv()?, &container)?;
    let url = format!("{}api/shares?expires={}", page, args.expires.as_str());
    let mut response = agent().post(&url).send(&sealed[..]).with_context(|| format!("cannot reach {url}"))?;
    let status = response.status().as_u16();
    let body = response.body_mut().read_to_vec()?;
    if status != 201 {
        return Err(api_failure("uploading the share", status, &body));
    }
    let created: CreatedShare = serde_json::from_slice(&body).context("the server's answer")?;
    let link = ShareLink { page, id: created.id, key, time: None };
    println!("{link}");
    eprintln!("shared {what} ({} bytes sealed), expires {}", sealed.len(), created.expires_at);
    eprintln!("delete token (keep it to delete the share): {}", created.delete_token);
    Ok(())
}

/// A folder written by `share get`, packed again (without its recording unless wanted).
fn reshare(folder: &std::path::Path, include_recording: bool) -> Result<(Vec<u8>, String)> {
    let read = |name: &str| {
        let path = folder.join(name);
        std::fs::read(&path).with_context(|| format!("cannot read {}", path.display()))
    };
    let manifest: egoexo_share::ShareManifest = serde_json::from_slice(&read(container::MANIFEST_FILE)?)
        .with_context(|| format!("{}/{}", folder.display(), container::MANIFEST_FILE))?;
    let motion: egoexo_core::SmplMotion = serde_json::from_slice(&read(container::MOTION_FILE)?)
        .with_context(|| format!("{}/{}", folder.display(), container::MOTION_FILE))?;
    let recording = folder.join(container::SESSION_FILE);
    let session_egoexo =
        if include_recording && recording.is_file() { Some(read(container::SESSION_FILE)?) } else { None };
    let what = format!(
        "`{}` again ({}{})",
        manifest.name,
        manifest.summary.method,
        if session_egoexo.is_some() { ", with the recording" } else { "" }
    );
    // A capture's participants: each one's scene and motion under `participants/<id>/`.
    let mut participants = Vec::new();
    for entry in &manifest.participants {
        let id = &entry.participant.id;
        let motion: egoexo_core::SmplMotion =
            serde_json::from_slice(&read(&container::participant_entry(id, container::MOTION_FILE)?)?)
                .with_context(|| format!("{}: participant `{id}`'s motion", folder.display()))?;
        participants.push(egoexo_share::SharedParticipant {
            entry: entry.clone(),
            scene_json: read(&container::participant_entry(id, container::SCENE_FILE)?)?,
            motion,
        });
    }
    let contents = egoexo_share::ShareContents {
        manifest,
        scene_json: read(container::SCENE_FILE)?,
        motion,
        session_egoexo,
        participants,
    };
    Ok((egoexo_share::pack(&contents)?, what))
}

/// Reconstructs a session as the page does and packs it.
fn reconstruct_and_pack(session: &std::path::Path, args: &CreateArgs) -> Result<(Vec<u8>, String)> {
    let mut worker = SessionWorker::new();
    let dir = models_dir(args.models.as_deref());
    let manifest = std::fs::read(dir.join("manifest.json"))
        .with_context(|| format!("cannot read {}/manifest.json", dir.display()))?;
    worker.load_models(&manifest, |file| {
        std::fs::read(dir.join(file)).map_err(|e| egoexo_infer::InferError::ReadModel {
            file: dir.join(file).display().to_string(),
            message: e.to_string(),
        })
    })?;
    let imported = args.import.import(session)?;
    for warning in &imported.warnings {
        eprintln!("warning: {warning}");
    }
    let session = worker.open_imported(imported)?;
    let bar = ProgressBar::new(0).with_style(
        ProgressStyle::with_template("{msg:>16} {bar:40} {pos}/{len} steps [{elapsed_precise}]")
            .unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let summary = worker.reconstruct(true, &mut |p| {
        bar.set_message(p.stage.label());
        bar.set_length(p.total as u64);
        bar.set_position(p.done as u64);
        true
    })?;
    bar.finish_and_clear();

    let container = worker.pack_share(!args.no_recording, CREATED_BY)?;
    let what = format!(
        "`{}` ({} frames, {}{})",
        session.name,
        summary.frames,
        summary.method,
        if args.no_recording { "" } else { ", with the recording" }
    );
    Ok((container, what))
}

/// The link and the share's API address (`--server`, else the link's origin).
fn share_at(link: &str, server: Option<&str>) -> Result<(ShareLink, String)> {
    let link = ShareLink::parse(link).map_err(anyhow::Error::msg)?;
    let api = match server {
        Some(server) => server.to_string(),
        None => link.page_origin().context("the link has no http(s) origin; pass --server")?.to_string(),
    };
    let url = link.api_url(&api);
    Ok((link, url))
}

fn run_delete(args: DeleteArgs) -> Result<()> {
    let (_, url) = share_at(&args.link, args.server.as_deref())?;
    let mut response = agent()
        .delete(&url)
        .header("Authorization", &format!("Bearer {}", args.token.trim()))
        .call()
        .with_context(|| format!("cannot reach {url}"))?;
    let status = response.status().as_u16();
    let body = response.body_mut().read_to_vec()?;
    if status != 204 {
        return Err(api_failure("deleting the share", status, &body));
    }
    eprintln!("deleted: the link no longer opens");
    Ok(())
}

fn run_get(args: GetArgs) -> Result<()> {
    let (link, url) = share_at(&args.link, args.server.as_deref())?;
    let mut response = agent().get(&url).call().with_context(|| format!("cannot reach {url}"))?;
    let status = response.status().as_u16();
    let body = response.body_mut().with_config().limit(1 << 34).read_to_vec()?;
    if status != 200 {
        return Err(api_failure("downloading the share", status, &body));
    }
    let container = envelope::open(&link.key, &body)?;
    let mut worker = SessionWorker::new();
    let opened = worker.open_share(container.clone())?;
    let contents = egoexo_share::unpack(container)?;
    std::fs::create_dir_all(&args.output).with_context(|| format!("creating {}", args.output.display()))?;
    let mut files: Vec<(String, Vec<u8>)> = vec![
        (egoexo_share::container::MANIFEST_FILE.into(), serde_json::to_vec_pretty(&opened.manifest)?),
        (egoexo_share::container::SCENE_FILE.into(), opened.scene_json),
        (egoexo_share::container::MOTION_FILE.into(), serde_json::to_vec(&contents.motion)?),
    ];
    if let Some(recording) = contents.session_egoexo {
        files.push((egoexo_share::container::SESSION_FILE.into(), recording));
    }
    for format in ExportFormat::ALL {
        let file = worker.export(format)?;
        files.push((file.file_name, file.bytes));
    }
    // A capture: every participant's scene, motion and exports (the exports named by them).
    for p in &contents.participants {
        let id = &p.entry.participant.id;
        files.push((
            egoexo_share::container::participant_entry(id, egoexo_share::container::SCENE_FILE)?,
            p.scene_json.clone(),
        ));
        files.push((
            egoexo_share::container::participant_entry(id, egoexo_share::container::MOTION_FILE)?,
            serde_json::to_vec(&p.motion)?,
        ));
        if Some(id) != opened.manifest.summary.participant.as_ref() {
            worker.select_participant(id)?;
            for format in ExportFormat::ALL {
                let file = worker.export(format)?;
                files.push((file.file_name, file.bytes));
            }
        }
    }
    for (name, bytes) in &files {
        let path = args.output.join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).with_context(|| format!("creating {}", parent.display()))?;
        }
        if path.exists() && !args.force {
            bail!("{} exists; pass --force to replace it", path.display());
        }
        std::fs::write(&path, bytes).with_context(|| format!("cannot write {}", path.display()))?;
        println!("{}", path.display());
    }
    eprintln!(
        "`{}`: {} frames ({}), made by {}{}",
        opened.manifest.name,
        opened.manifest.summary.frames,
        opened.manifest.summary.method,
        opened.manifest.created_by,
        if opened.manifest.includes_recording { ", with the recording" } else { "" }
    );
    Ok(())
}
