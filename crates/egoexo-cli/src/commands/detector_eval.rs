//! `egoexo detector-eval --coco <annotations.json>`: the shipped detector on photographs with
//! human-made COCO keypoint labels — PCK and OKS on the whole frame vs on the region a
//! proposal would give (`egoexo_detect::photos`). Reads COCO val2017's
//! `person_keypoints_val2017.json` as well as a small file of a few images.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use egoexo_detect::photos::{CocoKeypoints, PersonScore, PhotoCrop, PhotoSummary, detect_in_window, score_person};

use super::detection::load_detector;
use super::models::{models_dir, read_manifest};

#[derive(clap::Args)]
pub struct Args {
    /// A COCO person-keypoints annotation file (`images`, `annotations` with 17 keypoints).
    #[arg(long)]
    pub coco: PathBuf,
    /// The folder holding the images the file names [default: the annotation file's folder].
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Also score regions shifted by this fraction of their side, left, right, up and down (a
    /// coarse pose that is off); 0 leaves them out.
    #[arg(long, default_value_t = 0.1)]
    pub shift: f32,
    /// Score only the first N images of the file.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Models folder [default: ./models, else the repository's models/].
    #[arg(long)]
    pub models: Option<PathBuf>,
    /// Also print the figures as JSON on stdout.
    #[arg(long)]
    pub json: bool,
}

/// What one way of cropping gave, person by person.
#[derive(Default)]
struct CropScores {
    /// People alone in their image's annotations.
    alone: Vec<PersonScore>,
    among_others: Vec<PersonScore>,
    /// Milliseconds per detection (crop + model).
    ms: Vec<f64>,
}

/// The figures of one way of cropping.
#[derive(serde::Serialize)]
struct CropReport {
    crop: PhotoCrop,
    label: String,
    all: PhotoSummary,
    /// People alone in their image's annotations, and people among others.
    alone: PhotoSummary,
    among_others: PhotoSummary,
    /// Median milliseconds per detection (crop + model).
    median_ms: f64,
}

pub fn run(args: Args) -> Result<()> {
    if !(0.0..1.0).contains(&args.shift) {
        bail!("--shift {}: expected a fraction of the region's side in [0, 1)", args.shift);
    }
    let text = std::fs::read_to_string(&args.coco).with_context(|| format!("cannot read {}", args.coco.display()))?;
    let coco = CocoKeypoints::from_json(&args.coco.display().to_string(), &text)?;
    let folder = match args.images {
        Some(folder) => folder,
        None => args.coco.parent().map(PathBuf::from).unwrap_or_default(),
    };
    let models = models_dir(args.models.as_deref());
    let detector = load_detector(&models, &read_manifest(&models)?)?;

    let mut crops = vec![PhotoCrop::FullFrame, PhotoCrop::Region];
    if args.shift > 0.0 {
        let s = args.shift;
        crops.extend([[-s, 0.0], [s, 0.0], [0.0, -s], [0.0, s]].map(|offset| PhotoCrop::ShiftedRegion { offset }));
    }
    let mut results: Vec<CropScores> = crops.iter().map(|_| CropScores::default()).collect();
    let images: Vec<_> = coco
        .images
        .iter()
        .filter(|i| coco.people_in(i.id).next().is_some())
        .take(args.limit.unwrap_or(usize::MAX))
        .collect();
    if images.is_empty() {
        bail!("{}: no image has a labelled person to score", args.coco.display());
    }
    for image in &images {
        let path = folder.join(&image.file_name);
        let decoded = image::open(&path).with_context(|| format!("cannot decode {}", path.display()))?.to_rgb8();
        if decoded.dimensions() != (image.width, image.height) {
            bail!(
                "{} is {}×{} px; {} says image {} is {}×{}",
                path.display(),
                decoded.width(),
                decoded.height(),
                args.coco.display(),
                image.id,
                image.width,
                image.height
            );
        }
        let people: Vec<_> = coco.people_in(image.id).collect();
        let alone = people.len() == 1;
        for (c, crop) in crops.iter().enumerate() {
            let entry = &mut results[c];
            // The full frame is one detection per image, scored against each person in it.
            let mut full_frame = None;
            for person in &people {
                let Some(window) = crop.window(person, image.width, image.height) else { continue };
                let detected = match (crop, full_frame) {
                    (PhotoCrop::FullFrame, Some(detected)) => detected,
                    _ => {
                        let started = Instant::now();
                        let detected = detect_in_window(
                            &detector,
                            &image.file_name,
                            &decoded,
                            image.width,
                            image.height,
                            &window,
                        )?;
                        entry.ms.push(started.elapsed().as_secs_f64() * 1e3);
                        full_frame = Some(detected);
                        detected
                    }
                };
                let score = score_person(person, &detected);
                if alone { entry.alone.push(score) } else { entry.among_others.push(score) }
            }
        }
    }

    let reports: Vec<CropReport> = results
        .into_iter()
        .zip(&crops)
        .map(|(mut scores, crop)| {
            scores.ms.sort_by(f64::total_cmp);
            CropReport {
                crop: *crop,
                label: crop.label(),
                all: PhotoSummary::of(scores.alone.iter().chain(&scores.among_others)),
                alone: PhotoSummary::of(&scores.alone),
                among_others: PhotoSummary::of(&scores.among_others),
                median_ms: scores.ms.get(scores.ms.len() / 2).copied().unwrap_or(f64::NAN),
            }
        })
        .collect();
    let first = &reports[0].all;
    println!(
        "{}: {} images, {} people, {} labelled keypoints (model {}, keypoints scoring under {} dropped)",
        args.coco.display(),
        images.len(),
        first.people,
        first.keypoints,
        detector.manifest().model,
        egoexo_detect::MIN_KEYPOINT_SCORE
    );
    println!(
        "| crop | kept | PCK@0.1 | PCK@0.2 | mean OKS | PCK@0.2, alone in the image ({}) | among others ({}) | ms/detection |",
        reports[0].alone.people, reports[0].among_others.people
    );
    println!("|---|---:|---:|---:|---:|---:|---:|---:|");
    let pck = |s: &PhotoSummary| if s.people == 0 { "–".to_string() } else { format!("{:.3}", s.pck_02) };
    for r in &reports {
        println!(
            "| {} | {:.3} | {:.3} | {:.3} | {:.3} | {} | {} | {:.1} |",
            r.label,
            r.all.found as f32 / r.all.keypoints.max(1) as f32,
            r.all.pck_01,
            r.all.pck_02,
            r.all.mean_oks,
            pck(&r.alone),
            pck(&r.among_others),
            r.median_ms
        );
    }
    if args.json {
        println!("{}", serde_json::to_string(&reports)?);
    }
    Ok(())
}
