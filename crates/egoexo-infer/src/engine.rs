//! The reconstruction engine: the trained networks per tracking mode and the baselines' data
//! ([`Engine`]), and every model set of a manifest loaded once ([`LoadedModels`]). Running it
//! is the job's ([`crate::job`]: `Engine::start`, `Engine::reconstruct`), so this module sits
//! below the job and the job below nothing that imports it back.
//!
//! [`Engine::reconstruct`] is a [`ReconstructionJob`](crate::job::ReconstructionJob) run to the end:
//! [plan](crate::plan) (tracking mode, tracked spans, windows, observer slots) → per window,
//! the [ego pass](crate::passes::ego_pass) (ego features, EgoNet's coarse pose) → per window
//! and method, the [exo pass](crate::passes::exo_pass) (regions, canonical rays, gate) and the
//! [fusion pass](crate::passes::fusion_pass) → [decode](crate::decode) (cross-fade, world
//! frame, root translation from the head by FK).
//!
//! The same engine runs the networks (`ego-only`, `ego-exo`, `ego-exo-ungated`) and the
//! baselines (`rest-pose`, `nearest-neighbour`), natively and in the browser's worker. Units:
//! metres, seconds; world Y-up.

use std::collections::BTreeMap;

use egoexo_core::ego_features::TrackingMode;

use crate::InferError;
use crate::baselines::NearestNeighbourIndex;
use crate::manifest::Manifest;
use crate::models::{Loading, ModelSet, NetworkRuns};
use crate::passes::CoarsePoseSource;
use crate::reconstruction::CoarsePose;

/// The engine: the trained networks (per tracking mode) and the baselines' data.
#[derive(Clone, Debug, Default)]
pub struct Engine {
    models: BTreeMap<u8, ModelSet>,
    nearest: BTreeMap<u8, NearestNeighbourIndex>,
}

impl Engine {
    /// An engine without networks (baselines only until models are added).
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds the networks of one tracking mode.
    pub fn with_models(mut self, models: ModelSet) -> Self {
        self.models.insert(models.manifest.tracking.points(), models);
        self
    }

    /// Adds a nearest-neighbour index for one tracking mode.
    pub fn with_nearest_neighbour(mut self, tracking: TrackingMode, index: NearestNeighbourIndex) -> Self {
        self.nearest.insert(tracking.points(), index);
        self
    }

    /// The loaded networks of a tracking mode.
    pub fn models(&self, tracking: TrackingMode) -> Option<&ModelSet> {
        self.models.get(&tracking.points())
    }

    /// Whether the networks of `tracking` are a live variant trained to be read out
    /// `lookahead` frames before the window's newest frame (else they are the offline ones, or
    /// none are loaded).
    pub fn trained_for_lookahead(&self, tracking: TrackingMode, lookahead: usize) -> bool {
        self.models(tracking).is_some_and(|m| m.manifest.lookahead == Some(lookahead))
    }

    /// The loaded networks of a tracking mode, or the error that names the mode.
    pub(crate) fn require_models(&self, tracking: TrackingMode) -> Result<&ModelSet, InferError> {
        self.models(tracking).ok_or(InferError::NoModels { points: tracking.points() })
    }

    /// The model or index behind a coarse-pose source in a tracking mode.
    pub(crate) fn coarse_pose_source(
        &self,
        coarse: CoarsePose,
        tracking: TrackingMode,
    ) -> Result<CoarsePoseSource<'_>, InferError> {
        Ok(match coarse {
            CoarsePose::RestPose => CoarsePoseSource::RestPose,
            CoarsePose::NearestNeighbour => CoarsePoseSource::NearestNeighbour(
                self.nearest
                    .get(&tracking.points())
                    .ok_or(InferError::NoNearestNeighbourIndex { points: tracking.points() })?,
            ),
            CoarsePose::EgoNet => CoarsePoseSource::EgoNet(&self.require_models(tracking)?.egonet),
        })
    }

    /// How often each network of every loaded mode has run, summed over the modes.
    pub fn network_runs(&self) -> NetworkRuns {
        self.models.values().map(ModelSet::runs).fold(NetworkRuns::default(), |a, b| a + b)
    }
}

/// Every model set of a manifest, each file parsed once: an engine with the offline networks
/// (what recordings use) and, per lookahead that live variants were trained for, an engine
/// with those variants (and the offline networks of modes without one).
#[derive(Clone, Debug, Default)]
pub struct LoadedModels {
    offline: Engine,
    live: BTreeMap<usize, Engine>,
}

impl LoadedModels {
    /// Loads every set of `manifest`, reading each file through `read` (a path relative to the
    /// models folder → bytes) once and checking its sha256.
    pub fn load(
        manifest: &Manifest,
        read: impl FnMut(&str) -> Result<Vec<u8>, InferError>,
    ) -> Result<Self, InferError> {
        Self::load_with(manifest, read, Loading::Now)
    }

    /// [`Self::load`], parsing and optimising the networks now or on first use.
    pub fn load_with(
        manifest: &Manifest,
        mut read: impl FnMut(&str) -> Result<Vec<u8>, InferError>,
        loading: Loading,
    ) -> Result<Self, InferError> {
        let mut loaded = Vec::new();
        let mut offline_sets = Vec::new();
        let mut live_sets: BTreeMap<usize, Vec<ModelSet>> = BTreeMap::new();
        for set in &manifest.model_sets {
            let models = ModelSet::load_sharing(set, &mut read, &mut loaded, loading)?;
            match set.lookahead {
                None => offline_sets.push(models),
                Some(lookahead) => live_sets.entry(lookahead).or_default().push(models),
            }
        }
        let offline = offline_sets.iter().cloned().fold(Engine::new(), Engine::with_models);
        let live = live_sets
            .into_iter()
            .map(|(lookahead, sets)| (lookahead, sets.into_iter().fold(offline.clone(), Engine::with_models)))
            .collect();
        Ok(Self { offline, live })
    }

    /// The offline networks.
    pub fn offline(&self) -> &Engine {
        &self.offline
    }

    /// The networks to read windows out at `lookahead` frames before their newest frame: the
    /// live variants trained for it where shipped, the offline networks otherwise (per mode;
    /// [`Engine::trained_for_lookahead`] tells which).
    pub fn for_lookahead(&self, lookahead: usize) -> &Engine {
        self.live.get(&lookahead).unwrap_or(&self.offline)
    }

    /// How often the offline networks have run since loading. The EgoNet they share with live
    /// variants counts every run; the variants' own gates and fusion networks are not counted.
    pub fn network_runs(&self) -> NetworkRuns {
        self.offline.network_runs()
    }
}
