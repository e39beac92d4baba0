//! ONNX models run by tract: loaded from bytes (the browser fetches them; nothing is
//! compiled into the binary), checked against the manifest, optimised once for their fixed
//! input shapes, and reused for every window.

use std::io::Cursor;
use std::ops::{Add, Sub};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use serde::{Deserialize, Serialize};
use tract_onnx::prelude::*;

use crate::InferError;
use crate::manifest::{ModelFile, ModelSetManifest, sha256_hex};

/// One optimised ONNX graph with fixed input shapes. Clones share the graph and the run
/// counter. A model loaded with [`OnnxModel::load_deferred`] keeps its (checked) bytes and is
/// parsed and optimised on its first run or [`OnnxModel::prepare`] — the browser's worker
/// loads every tracking mode's networks that way, so a session only pays for its own mode.
#[derive(Clone)]
pub struct OnnxModel {
    name: String,
    plan: Arc<OnceLock<Result<Arc<TypedRunnableModel>, String>>>,
    /// The file's bytes until the plan is made (deferred models only).
    pending: Arc<Mutex<Option<Vec<u8>>>>,
    input_shapes: Vec<Vec<usize>>,
    runs: Arc<AtomicU64>,
}

impl std::fmt::Debug for OnnxModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxModel")
            .field("name", &self.name)
            .field("input_shapes", &self.input_shapes)
            .field("ready", &self.is_ready())
            .finish()
    }
}

/// Parses, types with `input_shapes` (all `f32`), optimises and plans a model.
fn optimised_plan(bytes: &[u8], input_shapes: &[Vec<usize>]) -> Result<Arc<TypedRunnableModel>, String> {
    let err = |e: TractError| format!("{e:#}");
    let mut model = tract_onnx::onnx().model_for_read(&mut Cursor::new(bytes)).map_err(err)?;
    for (i, shape) in input_shapes.iter().enumerate() {
        model = model.with_input_fact(i, f32::fact(shape).into()).map_err(err)?;
    }
    model.into_optimized().map_err(err)?.into_runnable().map_err(err)
}

impl OnnxModel {
    /// Parses, types with `input_shapes` (all `f32`), optimises and plans a model.
    pub fn load(name: &str, bytes: &[u8], input_shapes: &[Vec<usize>]) -> Result<Self, InferError> {
        let plan = optimised_plan(bytes, input_shapes)
            .map_err(|message| InferError::Model { model: name.to_string(), message })?;
        Ok(Self {
            name: name.to_string(),
            plan: Arc::new(OnceLock::from(Ok(plan))),
            pending: Arc::default(),
            input_shapes: input_shapes.to_vec(),
            runs: Arc::default(),
        })
    }

    /// A model parsed and optimised on its first run or [`Self::prepare`] (whose error, a
    /// malformed file, comes then).
    pub fn load_deferred(name: &str, bytes: Vec<u8>, input_shapes: &[Vec<usize>]) -> Self {
        Self {
            name: name.to_string(),
            plan: Arc::default(),
            pending: Arc::new(Mutex::new(Some(bytes))),
            input_shapes: input_shapes.to_vec(),
            runs: Arc::default(),
        }
    }

    /// Whether the model is parsed and optimised (or failed to be).
    pub fn is_ready(&self) -> bool {
        self.plan.get().is_some()
    }

    /// Parses and optimises a deferred model now (nothing for one already made).
    pub fn prepare(&self) -> Result<(), InferError> {
        self.plan().map(|_| ())
    }

    fn plan(&self) -> Result<&Arc<TypedRunnableModel>, InferError> {
        let plan = self.plan.get_or_init(|| {
            let bytes = self.pending.lock().map_err(|_| "a run panicked while the model loaded".to_string())?.take();
            optimised_plan(&bytes.unwrap_or_default(), &self.input_shapes)
        });
        plan.as_ref().map_err(|message| InferError::Model { model: self.name.clone(), message: message.clone() })
    }

    /// How many times the model has run (successfully or not) since it was loaded.
    pub fn runs(&self) -> u64 {
        self.runs.load(Ordering::Relaxed)
    }

    /// The model's name (for errors).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Runs on row-major `f32` inputs in declaration order; returns every output flattened.
    pub fn run(&self, inputs: &[&[f32]]) -> Result<Vec<Vec<f32>>, InferError> {
        self.runs.fetch_add(1, Ordering::Relaxed);
        if inputs.len() != self.input_shapes.len() {
            return Err(InferError::Model {
                model: self.name.clone(),
                message: format!("expected {} inputs, got {}", self.input_shapes.len(), inputs.len()),
            });
        }
        let err = |e: TractError| InferError::Model { model: self.name.clone(), message: format!("{e:#}") };
        let mut values = TVec::new();
        for (data, shape) in inputs.iter().zip(&self.input_shapes) {
            if data.len() != shape.iter().product::<usize>() {
                return Err(InferError::Model {
                    model: self.name.clone(),
                    message: format!("input of {} numbers does not fit shape {shape:?}", data.len()),
                });
            }
            values.push(Tensor::from_shape(shape, data).map_err(err)?.into());
        }
        let outputs = self.plan()?.run(values).map_err(err)?;
        outputs.iter().map(|t| Ok(t.to_plain_array_view::<f32>().map_err(err)?.iter().copied().collect())).collect()
    }
}

/// The networks of one tracking mode.
#[derive(Clone, Debug)]
pub struct ModelSet {
    pub manifest: ModelSetManifest,
    pub egonet: OnnxModel,
    pub gate: OnnxModel,
    pub fusion: OnnxModel,
    /// The fusion with every observer masked, when the set ships it
    /// ([`ModelSetManifest::fusion_ego_only`]).
    pub fusion_ego_only: Option<OnnxModel>,
}

/// How often each network has run (one run = one window).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct NetworkRuns {
    pub egonet: u64,
    pub gate: u64,
    pub fusion: u64,
    #[serde(default)]
    pub fusion_ego_only: u64,
}

impl Add for NetworkRuns {
    type Output = NetworkRuns;

    fn add(self, o: NetworkRuns) -> NetworkRuns {
        NetworkRuns {
            egonet: self.egonet + o.egonet,
            gate: self.gate + o.gate,
            fusion: self.fusion + o.fusion,
            fusion_ego_only: self.fusion_ego_only + o.fusion_ego_only,
        }
    }
}

impl Sub for NetworkRuns {
    type Output = NetworkRuns;

    /// Runs between two readings (saturating).
    fn sub(self, o: NetworkRuns) -> NetworkRuns {
        NetworkRuns {
            egonet: self.egonet.saturating_sub(o.egonet),
            gate: self.gate.saturating_sub(o.gate),
            fusion: self.fusion.saturating_sub(o.fusion),
            fusion_ego_only: self.fusion_ego_only.saturating_sub(o.fusion_ego_only),
        }
    }
}

impl ModelSet {
    /// How often each network has run.
    pub fn runs(&self) -> NetworkRuns {
        NetworkRuns {
            egonet: self.egonet.runs(),
            gate: self.gate.runs(),
            fusion: self.fusion.runs(),
            fusion_ego_only: self.fusion_ego_only.as_ref().map_or(0, OnnxModel::runs),
        }
    }

    /// Loads a model set, reading each file through `read` (a path relative to the models
    /// folder → bytes) and checking its sha256 against the manifest.
    pub fn load(
        manifest: &ModelSetManifest,
        mut read: impl FnMut(&str) -> Result<Vec<u8>, InferError>,
    ) -> Result<Self, InferError> {
        Self::load_sharing(manifest, &mut read, &mut Vec::new(), Loading::Now)
    }

    /// Parses and optimises every network of the set that is not yet (deferred loading).
    pub fn prepare(&self) -> Result<(), InferError> {
        self.networks().try_for_each(OnnxModel::prepare)
    }

    /// Whether every network of the set is parsed and optimised.
    pub fn is_ready(&self) -> bool {
        self.networks().all(OnnxModel::is_ready)
    }

    /// The first network of the set not yet parsed and optimised.
    pub fn next_unprepared(&self) -> Option<&OnnxModel> {
        self.networks().find(|n| !n.is_ready())
    }

    fn networks(&self) -> impl Iterator<Item = &OnnxModel> {
        [Some(&self.egonet), Some(&self.gate), Some(&self.fusion), self.fusion_ego_only.as_ref()].into_iter().flatten()
    }

    /// [`ModelSet::load`] reusing the models already in `loaded` (by file and sha256) and
    /// adding the ones it loads.
    pub(crate) fn load_sharing(
        manifest: &ModelSetManifest,
        read: &mut dyn FnMut(&str) -> Result<Vec<u8>, InferError>,
        loaded: &mut Vec<(ModelFile, OnnxModel)>,
        loading: Loading,
    ) -> Result<Self, InferError> {
        let mut load = |file: &ModelFile| -> Result<OnnxModel, InferError> {
            if let Some((_, model)) = loaded.iter().find(|(f, _)| f.file == file.file && f.sha256 == file.sha256) {
                return Ok(model.clone());
            }
            let bytes = read(&file.file)?;
            let digest = sha256_hex(&bytes);
            if digest != file.sha256 {
                return Err(InferError::Checksum {
                    file: file.file.clone(),
                    expected: file.sha256.clone(),
                    actual: digest,
                });
            }
            let shapes: Vec<Vec<usize>> = file.inputs.iter().map(|i| i.shape.clone()).collect();
            let model = match loading {
                Loading::Now => OnnxModel::load(&file.file, &bytes, &shapes)?,
                Loading::Deferred => OnnxModel::load_deferred(&file.file, bytes, &shapes),
            };
            loaded.push((file.clone(), model.clone()));
            Ok(model)
        };
        Ok(Self {
            egonet: load(&manifest.egonet)?,
            gate: load(&manifest.gate)?,
            fusion: load(&manifest.fusion)?,
            fusion_ego_only: manifest.fusion_ego_only.as_ref().map(&mut load).transpose()?,
            manifest: manifest.clone(),
        })
    }
}

/// When a network is parsed and optimised: as it is loaded, or on its first use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Loading {
    Now,
    /// [`OnnxModel::load_deferred`]: the files are read and checked now, each network is
    /// parsed and optimised on its first run or [`ModelSet::prepare`].
    Deferred,
}
