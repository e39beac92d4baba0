//! Native helpers: finding CMU files on disk, importing a whole tree in parallel, and
//! reading and writing library files. Everything else in the crate works on bytes.
//!
//! Two layouts are recognised, anywhere below the given folder (up to [`MAX_SCAN_DEPTH`]
//! levels): the project's subset (`cmu/NN/NN.asf`, `cmu/NN/NN_TT.amc`, `cmu/CMU_data.csv`)
//! and CMU's own `allasfamc.zip` (`all_asfamc/subjects/NN/NN.asf`, `…/NN_TT.amc`). A subject
//! is a folder holding `NN.asf`; its trials are the `NN_TT.amc` files beside it. Trials in
//! BVH form (`NN_TT.bvh`, anywhere) are imported too, unless the same trial is there as AMC.

use std::path::{Path, PathBuf};

use rayon::prelude::*;

use crate::bvh::import_bvh_trial;
use crate::catalog::Catalog;
use crate::import::{CMU_SOURCE, ImportError, ImportOptions, SubjectImporter, TrialImport, parse_trial_name};
use crate::library::{LibraryError, MotionLibrary};

/// How deep below the given folder files are looked for.
pub const MAX_SCAN_DEPTH: usize = 6;

/// The files of one subject.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SubjectFiles {
    pub subject: u32,
    pub asf: PathBuf,
    /// `(trial, path)`, ascending by trial.
    pub trials: Vec<(u32, PathBuf)>,
}

/// CMU files found below a folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CmuTree {
    /// The folders searched, in the order given.
    pub roots: Vec<PathBuf>,
    /// The shallowest `CMU_data.csv`, if any.
    pub catalog: Option<PathBuf>,
    /// Subjects with an ASF, ascending.
    pub subjects: Vec<SubjectFiles>,
    /// Trials in BVH form: `(subject, trial, path)`, ascending.
    pub bvh_trials: Vec<(u32, u32, PathBuf)>,
    /// `.asf`/`.amc` files that were not used, with the reason.
    pub ignored: Vec<(PathBuf, String)>,
}

impl CmuTree {
    /// The searched folders, comma-separated (for messages).
    pub fn display_roots(&self) -> String {
        self.roots.iter().map(|r| r.display().to_string()).collect::<Vec<_>>().join(", ")
    }

    /// Number of trials (AMC and BVH).
    pub fn trial_count(&self) -> usize {
        self.subjects.iter().map(|s| s.trials.len()).sum::<usize>() + self.bvh_trials.len()
    }

    /// Trials of the chosen subjects (all when `None`).
    pub fn trial_count_of(&self, subjects: Option<&[u32]>) -> usize {
        let chosen = |s: u32| subjects.is_none_or(|list| list.contains(&s));
        self.subjects.iter().filter(|s| chosen(s.subject)).map(|s| s.trials.len()).sum::<usize>()
            + self.bvh_trials.iter().filter(|t| chosen(t.0)).count()
    }

    /// Every subject with at least one trial, ascending.
    pub fn subject_numbers(&self) -> Vec<u32> {
        let mut all: Vec<u32> =
            self.subjects.iter().map(|s| s.subject).chain(self.bvh_trials.iter().map(|t| t.0)).collect();
        all.sort_unstable();
        all.dedup();
        all
    }
}

fn io_error(path: &Path, source: std::io::Error) -> ImportError {
    ImportError::Io { path: path.display().to_string(), source }
}

fn has_extension(path: &Path, ext: &str) -> bool {
    path.extension().and_then(|e| e.to_str()).is_some_and(|e| e.eq_ignore_ascii_case(ext))
}

/// Finds the CMU subjects, trials and catalogue below `root`.
pub fn scan_cmu_tree(root: &Path) -> Result<CmuTree, ImportError> {
    scan_cmu_trees(&[root.to_path_buf()])
}

/// Finds the CMU subjects, trials and catalogue below each of `roots`, as one tree (e.g. the
/// shared subset and `cmu-extra`). A subject's ASF found twice is used from the first root;
/// a trial present as AMC anywhere is never imported from BVH.
pub fn scan_cmu_trees(roots: &[PathBuf]) -> Result<CmuTree, ImportError> {
    // A stack: the last folder pushed is searched first, so push the roots in reverse.
    let mut folders: Vec<(usize, PathBuf)> = roots.iter().rev().map(|r| (0, r.clone())).collect();
    let mut catalog: Option<(usize, PathBuf)> = None;
    let mut subjects: Vec<SubjectFiles> = Vec::new();
    let mut ignored = Vec::new();
    let mut orphan_amcs: Vec<PathBuf> = Vec::new();
    let mut bvh_trials: Vec<(u32, u32, PathBuf)> = Vec::new();
    while let Some((depth, folder)) = folders.pop() {
        let mut entries: Vec<PathBuf> = std::fs::read_dir(&folder)
            .map_err(|e| io_error(&folder, e))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .collect();
        entries.sort();
        let mut asfs = Vec::new();
        let mut amcs = Vec::new();
        for path in entries {
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if name.starts_with('.') {
                continue;
            }
            if path.is_dir() {
                if depth < MAX_SCAN_DEPTH {
                    folders.push((depth + 1, path));
                }
            } else if name.eq_ignore_ascii_case("CMU_data.csv") {
                if catalog.as_ref().is_none_or(|(d, _)| depth < *d) {
                    catalog = Some((depth, path));
                }
            } else if has_extension(&path, "asf") {
                asfs.push(path);
            } else if has_extension(&path, "amc") {
                amcs.push(path);
            } else if has_extension(&path, "bvh") {
                let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("");
                match parse_trial_name(stem) {
                    Some((subject, trial)) => bvh_trials.push((subject, trial, path)),
                    None => ignored.push((path, "the name is not SUBJECT_TRIAL.bvh".to_owned())),
                }
            }
        }
        let stem = |p: &Path| p.file_stem().and_then(|s| s.to_str()).unwrap_or("").to_owned();
        let mut folder_subjects: Vec<usize> = Vec::new();
        for asf in asfs {
            match stem(&asf).parse::<u32>() {
                Ok(subject) if subjects.iter().any(|s| s.subject == subject) => {
                    ignored.push((asf, format!("subject {subject} was already found elsewhere")));
                }
                Ok(subject) => {
                    subjects.push(SubjectFiles { subject, asf, trials: Vec::new() });
                    folder_subjects.push(subjects.len() - 1);
                }
                Err(_) => ignored.push((asf, "the name is not SUBJECT.asf".to_owned())),
            }
        }
        for amc in amcs {
            let Some((subject, trial)) = parse_trial_name(&stem(&amc)) else {
                ignored.push((amc, "the name is not SUBJECT_TRIAL.amc".to_owned()));
                continue;
            };
            match folder_subjects.iter().find(|&&i| subjects[i].subject == subject) {
                Some(&i) => subjects[i].trials.push((trial, amc)),
                None => orphan_amcs.push(amc),
            }
        }
    }
    for amc in orphan_amcs {
        ignored.push((amc, "no SUBJECT.asf beside it".to_owned()));
    }
    subjects.retain(|s| !s.trials.is_empty());
    subjects.sort_by_key(|s| s.subject);
    for s in &mut subjects {
        s.trials.sort();
    }
    bvh_trials.sort();
    let mut kept_bvh: Vec<(u32, u32, PathBuf)> = Vec::new();
    for (subject, trial, path) in bvh_trials {
        let as_amc = subjects.iter().any(|s| s.subject == subject && s.trials.iter().any(|(t, _)| *t == trial));
        if as_amc {
            ignored.push((path, "the same trial is imported from its AMC".to_owned()));
        } else if kept_bvh.iter().any(|(s, t, _)| *s == subject && *t == trial) {
            ignored.push((path, "the same trial was already found elsewhere".to_owned()));
        } else {
            kept_bvh.push((subject, trial, path));
        }
    }
    if subjects.is_empty() && kept_bvh.is_empty() {
        let names: Vec<String> = roots.iter().map(|r| r.display().to_string()).collect();
        return Err(ImportError::EmptyTree(names.join(", ")));
    }
    Ok(CmuTree { roots: roots.to_vec(), catalog: catalog.map(|(_, p)| p), subjects, bvh_trials: kept_bvh, ignored })
}

/// Reads text that should be ASCII; stray non-UTF-8 bytes (in comments, file paths of the
/// original capture machine) become U+FFFD instead of failing the whole file.
pub fn read_text(path: &Path) -> Result<String, ImportError> {
    let bytes = std::fs::read(path).map_err(|e| io_error(path, e))?;
    Ok(match String::from_utf8(bytes) {
        Ok(s) => s,
        Err(e) => String::from_utf8_lossy(e.as_bytes()).into_owned(),
    })
}

/// Reads a `CMU_data.csv`.
pub fn read_catalog(path: &Path) -> Result<Catalog, ImportError> {
    let bytes = std::fs::read(path).map_err(|e| io_error(path, e))?;
    Ok(Catalog::parse(&bytes, &path.display().to_string())?)
}

/// What happened to one trial (for progress reporting).
#[derive(Debug)]
pub struct TrialOutcome<'a> {
    pub path: &'a Path,
    pub result: Result<&'a TrialImport, &'a ImportError>,
}

/// The result of importing a tree.
#[derive(Debug)]
pub struct TreeImport {
    pub library: MotionLibrary,
    /// Trials (or whole subjects) that could not be imported.
    pub failures: Vec<ImportError>,
    /// Trials imported.
    pub trials: usize,
    /// Per trial that lost frames to glitches: `(path, source frames, dropped frames)`.
    pub trimmed: Vec<(PathBuf, usize, usize)>,
    /// BVH trials whose prepended reference pose (T-pose row) was left out.
    pub reference_rows_skipped: Vec<PathBuf>,
    /// BVH trials whose collapsed thorax was restored, with the length (m).
    pub restored_thorax: Vec<(PathBuf, f32)>,
}

/// Imports every trial of `tree` (or only those of `subjects`) in parallel and builds the
/// library. A trial that fails is reported in [`TreeImport::failures`] and the others go
/// on; `progress` is called once per trial, from worker threads.
pub fn import_tree(
    tree: &CmuTree,
    catalog: &Catalog,
    options: &ImportOptions,
    subjects: Option<&[u32]>,
    progress: &(dyn Fn(TrialOutcome<'_>) + Sync),
) -> Result<TreeImport, ImportError> {
    let chosen: Vec<&SubjectFiles> =
        tree.subjects.iter().filter(|s| subjects.is_none_or(|list| list.contains(&s.subject))).collect();
    let importers: Vec<Result<SubjectImporter, ImportError>> = chosen
        .par_iter()
        .map(|s| {
            let text = read_text(&s.asf)?;
            SubjectImporter::new(s.subject, &text, &s.asf.display().to_string())
        })
        .collect();
    let mut failures = Vec::new();
    // (subject, trial, path, the subject's ASF importer — `None` for a BVH trial)
    let mut jobs: Vec<(u32, u32, &Path, Option<&SubjectImporter>)> = Vec::new();
    for (files, importer) in chosen.iter().zip(&importers) {
        if let Ok(importer) = importer {
            jobs.extend(files.trials.iter().map(|(t, p)| (files.subject, *t, p.as_path(), Some(importer))));
        }
    }
    for (subject, trial, path) in &tree.bvh_trials {
        if subjects.is_none_or(|list| list.contains(subject)) {
            jobs.push((*subject, *trial, path.as_path(), None));
        }
    }
    jobs.sort_by_key(|job| (job.0, job.1));
    let results: Vec<(&Path, Result<TrialImport, ImportError>)> = jobs
        .par_iter()
        .map(|&(subject, trial, path, importer)| {
            let file = path.display().to_string();
            let result = match catalog.get(subject, trial) {
                None => Err(ImportError::NotInCatalog { file, subject, trial }),
                Some(entry) => read_text(path).and_then(|text| match importer {
                    Some(importer) => importer.import_trial(trial, &text, &file, entry, options),
                    None => import_bvh_trial(&text, &file, subject, trial, entry, options),
                }),
            };
            progress(TrialOutcome { path, result: result.as_ref() });
            (path, result)
        })
        .collect();
    failures.extend(importers.into_iter().filter_map(Result::err));

    let mut clips = Vec::new();
    let mut trimmed = Vec::new();
    let mut reference_rows_skipped = Vec::new();
    let mut restored_thorax = Vec::new();
    let mut trials = 0;
    for (path, result) in results {
        match result {
            Ok(import) => {
                trials += 1;
                if let Some(length) = import.restored_thorax_m {
                    restored_thorax.push((path.to_path_buf(), length));
                }
                if import.reference_rows_skipped > 0 {
                    reference_rows_skipped.push(path.to_path_buf());
                }
                if import.dropped_frames > 0 {
                    trimmed.push((path.to_path_buf(), import.source_frames, import.dropped_frames));
                }
                clips.extend(import.clips);
            }
            Err(e) => failures.push(e),
        }
    }
    let library = MotionLibrary::build(options.fps, CMU_SOURCE, clips)
        .map_err(|source| ImportError::Library { file: tree.display_roots(), source })?;
    Ok(TreeImport { library, failures, trials, trimmed, reference_rows_skipped, restored_thorax })
}

/// Reads a library file.
pub fn open_library(path: &Path) -> Result<MotionLibrary, LibraryError> {
    let bytes = std::fs::read(path).map_err(|source| LibraryError::Io { path: path.display().to_string(), source })?;
    MotionLibrary::from_bytes(bytes)
}

/// Writes a library file (through a temporary file beside it, then a rename, so a reader
/// never sees half a library).
pub fn save_library(library: &MotionLibrary, path: &Path) -> Result<(), LibraryError> {
    let io = |source| LibraryError::Io { path: path.display().to_string(), source };
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".partial");
    let tmp = PathBuf::from(tmp);
    std::fs::write(&tmp, library.as_bytes()).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}
