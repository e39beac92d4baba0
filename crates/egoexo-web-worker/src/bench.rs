//! The bench page's network probe: one shipped network loaded alone, run on deterministic
//! inputs ([`egoexo_infer::cost::bench_inputs`]) so that another engine (onnxruntime-web, in
//! the same worker) can run the same numbers, with the network's FLOPs per run and a plain
//! matrix product of its dominant shape ([`egoexo_infer::cost::MatmulProbe`]) for the
//! attainable rate. The page times every call (nothing here reads a clock); in the browser it
//! is `NetworkBench` (`web/bench-networks.js`).

use egoexo_infer::InferError;
use egoexo_infer::cost::{MatmulProbe, MatmulShape, NetworkCost, bench_inputs, network_cost};
use egoexo_infer::manifest::{Manifest, ManifestError, ModelFile, NETWORK_NAMES};
use egoexo_infer::models::OnnxModel;

use crate::WorkerError;

/// One network, its inputs, and (after [`NetworkBench::analyse`]) its cost and probe.
#[derive(Debug)]
pub struct NetworkBench {
    file: ModelFile,
    bytes: Vec<u8>,
    model: OnnxModel,
    inputs: Vec<Vec<f32>>,
    analysis: Option<(NetworkCost, MatmulProbe)>,
}

impl NetworkBench {
    /// Loads and optimises `network` (one of [`NETWORK_NAMES`]) of the offline
    /// `points`-point set of `manifest_json` from its file's `bytes` (sha256-checked).
    pub fn load(manifest_json: &[u8], points: u8, network: &str, bytes: Vec<u8>) -> Result<Self, WorkerError> {
        let manifest = Manifest::from_json(manifest_json).map_err(WorkerError::Infer)?;
        let set = manifest.model_set_for_points(points).ok_or(WorkerError::Infer(InferError::NoModels { points }))?;
        let file = set
            .network(network)
            .ok_or_else(|| {
                WorkerError::Infer(InferError::Manifest(ManifestError::NoNetwork {
                    points,
                    network: network.to_owned(),
                    expected: NETWORK_NAMES.join(", "),
                }))
            })?
            .clone();
        let digest = egoexo_infer::manifest::sha256_hex(&bytes);
        if digest != file.sha256 {
            return Err(WorkerError::Infer(InferError::Checksum {
                file: file.file.clone(),
                expected: file.sha256.clone(),
                actual: digest,
            }));
        }
        let model = OnnxModel::load(&file.file, &bytes, &file.input_shapes()).map_err(WorkerError::Infer)?;
        let inputs = bench_inputs(&file.inputs);
        Ok(NetworkBench { file, bytes, model, inputs, analysis: None })
    }

    /// The manifest's entry of the network (input and output names and shapes).
    pub fn file(&self) -> &ModelFile {
        &self.file
    }

    /// The inputs every run uses, in declaration order.
    pub fn inputs(&self) -> &[Vec<f32>] {
        &self.inputs
    }

    /// One run; every output flattened and concatenated in declaration order.
    pub fn run(&self) -> Result<Vec<f32>, WorkerError> {
        let refs: Vec<&[f32]> = self.inputs.iter().map(Vec::as_slice).collect();
        Ok(self.model.run(&refs).map_err(WorkerError::Infer)?.concat())
    }

    /// Counts the FLOPs and builds the probe of the dominant product.
    pub fn analyse(&mut self) -> Result<(), WorkerError> {
        let cost = network_cost(&self.file.file, &self.bytes, &self.file.input_shapes()).map_err(WorkerError::Infer)?;
        let shape = cost.dominant_matmul().ok_or_else(|| {
            WorkerError::Infer(InferError::Model { model: self.file.file.clone(), message: "no matrix product".into() })
        })?;
        let probe = MatmulProbe::new(shape).map_err(WorkerError::Infer)?;
        self.analysis = Some((cost, probe));
        Ok(())
    }

    /// FLOPs per run and the probe's shape, once analysed.
    pub fn cost(&self) -> Option<(&NetworkCost, MatmulShape)> {
        self.analysis.as_ref().map(|(cost, probe)| (cost, probe.shape()))
    }

    /// Runs the probe once (its output's sum).
    pub fn run_probe(&self) -> Result<f32, WorkerError> {
        let (_, probe) = self.analysis.as_ref().ok_or(WorkerError::BenchNotAnalysed)?;
        probe.run().map_err(WorkerError::Infer)
    }
}

#[cfg(target_arch = "wasm32")]
mod js {
    use wasm_bindgen::prelude::*;

    fn js(e: crate::WorkerError) -> JsError {
        JsError::new(&e.to_string())
    }

    /// `new NetworkBench(manifestBytes, points, network, modelBytes)`: see the module docs.
    #[wasm_bindgen(js_name = NetworkBench)]
    #[derive(Debug)]
    pub struct JsNetworkBench(super::NetworkBench);

    #[wasm_bindgen(js_class = NetworkBench)]
    impl JsNetworkBench {
        #[wasm_bindgen(constructor)]
        pub fn new(manifest: &[u8], points: u8, network: &str, bytes: Vec<u8>) -> Result<JsNetworkBench, JsError> {
            super::NetworkBench::load(manifest, points, network, bytes).map(JsNetworkBench).map_err(js)
        }

        /// One run: every output flattened, concatenated in declaration order.
        pub fn run(&self) -> Result<Vec<f32>, JsError> {
            self.0.run().map_err(js)
        }

        #[wasm_bindgen(js_name = inputCount)]
        pub fn input_count(&self) -> usize {
            self.0.file().inputs.len()
        }

        #[wasm_bindgen(js_name = inputName)]
        pub fn input_name(&self, i: usize) -> Option<String> {
            self.0.file().inputs.get(i).map(|s| s.name.clone())
        }

        #[wasm_bindgen(js_name = inputShape)]
        pub fn input_shape(&self, i: usize) -> Option<Vec<u32>> {
            self.0.file().inputs.get(i).map(|s| s.shape.iter().map(|&d| d as u32).collect())
        }

        /// The values of input `i` (the same every run).
        pub fn input(&self, i: usize) -> Option<Vec<f32>> {
            self.0.inputs().get(i).cloned()
        }

        /// Output names in declaration order.
        #[wasm_bindgen(js_name = outputNames)]
        pub fn output_names(&self) -> Vec<String> {
            self.0.file().outputs.iter().map(|s| s.name.clone()).collect()
        }

        pub fn analyse(&mut self) -> Result<(), JsError> {
            self.0.analyse().map_err(js)
        }

        /// FLOPs per run (after `analyse`).
        pub fn flops(&self) -> f64 {
            self.0.cost().map_or(0.0, |(c, _)| c.flops as f64)
        }

        /// FLOPs of one probe run (after `analyse`).
        #[wasm_bindgen(js_name = probeFlops)]
        pub fn probe_flops(&self) -> f64 {
            self.0.cost().map_or(0.0, |(_, s)| s.flops() as f64)
        }

        /// `batch×(m×k)·(k×n)` of the probe.
        #[wasm_bindgen(js_name = probeShape)]
        pub fn probe_shape(&self) -> String {
            self.0.cost().map_or(String::new(), |(_, s)| format!("{}x({}x{})·({}x{})", s.batch, s.m, s.k, s.k, s.n))
        }

        #[wasm_bindgen(js_name = runProbe)]
        pub fn run_probe(&self) -> Result<f32, JsError> {
            self.0.run_probe().map_err(js)
        }
    }
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    fn fixtures() -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../egoexo-infer/tests/fixtures/models")
    }

    fn load(network: &str) -> Result<NetworkBench, WorkerError> {
        let manifest = std::fs::read(fixtures().join("manifest.json")).unwrap();
        let parsed = Manifest::from_json(&manifest).unwrap();
        let file = parsed.model_set_for_points(3).unwrap().network(network).unwrap_or(&parsed.model_sets[0].egonet);
        NetworkBench::load(&manifest, 3, network, std::fs::read(fixtures().join(&file.file)).unwrap())
    }

    #[test]
    fn a_network_runs_the_same_inputs_to_the_same_outputs_and_knows_its_cost() {
        for network in NETWORK_NAMES {
            let mut bench = load(network).unwrap();
            let out = bench.run().unwrap();
            let expected: usize = bench.file().outputs.iter().map(|o| o.shape.iter().product::<usize>()).sum();
            assert_eq!(out.len(), expected, "{network}");
            assert!(out.iter().all(|v| v.is_finite()), "{network}");
            assert_eq!(out, bench.run().unwrap(), "{network}: deterministic");
            assert!(bench.run_probe().is_err(), "no probe before analyse");
            bench.analyse().unwrap();
            let (cost, shape) = bench.cost().unwrap();
            assert!(cost.flops >= shape.flops(), "{network}: {cost:?}");
            assert!(bench.run_probe().unwrap().is_finite());
        }
    }

    #[test]
    fn a_wrong_network_or_file_is_refused_by_name() {
        let err = load("decoder").unwrap_err().to_string();
        assert!(err.contains("decoder") && err.contains("egonet, gate, fusion, fusion_ego_only"), "{err}");
        let manifest = std::fs::read(fixtures().join("manifest.json")).unwrap();
        let err = NetworkBench::load(&manifest, 3, "gate", b"not onnx".to_vec()).unwrap_err().to_string();
        assert!(err.contains("sha256"), "{err}");
    }
}
