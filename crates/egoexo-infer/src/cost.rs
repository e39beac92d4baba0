//! How much arithmetic a network is, and how fast this machine's tract kernels can do it.
//!
//! [`network_cost`] counts a network's floating-point operations per run (one 96-frame
//! window) from its ONNX graph, typed with the engine's input shapes: every op's tract cost
//! (an FMA is 2 FLOPs), and the matrix products among them with their shapes.
//! [`MatmulProbe`] is a graph holding one plain matrix product of a given shape, run by the
//! same engine (tract, with the same build's SIMD kernels): its FLOP/s is what that shape can
//! attain here, so a network's achieved FLOP/s over its largest product's probe says how much
//! of its time is arithmetic. The caller times both (the engine reads no clock).

use std::io::Cursor;

use serde::{Deserialize, Serialize};
use tract_onnx::prelude::*;
use tract_onnx::tract_core::internal::DimLike;
use tract_onnx::tract_core::ops::Cost;
use tract_onnx::tract_core::ops::einsum::EinSum;

use crate::InferError;

/// The shape of a (batched) matrix product: `batch × (m × k) · (k × n)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct MatmulShape {
    pub batch: usize,
    pub m: usize,
    pub k: usize,
    pub n: usize,
}

impl MatmulShape {
    /// FLOPs of one product (2 per multiply-add).
    pub fn flops(&self) -> u64 {
        2 * (self.batch * self.m * self.k * self.n) as u64
    }
}

/// A network's arithmetic per run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NetworkCost {
    /// Every op's FLOPs (2 per FMA, 1 per division), per run.
    pub flops: u64,
    /// The matrix products' share of `flops`.
    pub matmul_flops: u64,
    /// Each distinct product shape with how many times it occurs, most FLOPs first.
    pub matmuls: Vec<(MatmulShape, usize)>,
}

impl NetworkCost {
    /// The product shape with the most FLOPs in total.
    pub fn dominant_matmul(&self) -> Option<MatmulShape> {
        self.matmuls.first().map(|(shape, _)| *shape)
    }
}

fn model_err(name: &str) -> impl Fn(TractError) -> InferError + '_ {
    move |e| InferError::Model { model: name.to_string(), message: format!("{e:#}") }
}

/// Counts the FLOPs of one run of an ONNX network typed with `input_shapes` (all `f32`).
pub fn network_cost(name: &str, bytes: &[u8], input_shapes: &[Vec<usize>]) -> Result<NetworkCost, InferError> {
    let err = model_err(name);
    let mut model = tract_onnx::onnx().model_for_read(&mut Cursor::new(bytes)).map_err(&err)?;
    for (i, shape) in input_shapes.iter().enumerate() {
        model = model.with_input_fact(i, f32::fact(shape).into()).map_err(&err)?;
    }
    let model = model.into_typed().map_err(&err)?.into_decluttered().map_err(&err)?;
    let (mut flops, mut matmul_flops) = (0u64, 0u64);
    let mut matmuls: Vec<(MatmulShape, usize)> = Vec::new();
    for node in model.nodes() {
        let facts = model.node_input_facts(node.id).map_err(&err)?;
        let mut node_flops = 0u64;
        for (cost, count) in node.op.cost(&facts).map_err(&err)? {
            let count = count.to_i64().map_err(|_| InferError::Model {
                model: name.to_string(),
                message: format!("node `{}` has a cost of symbolic size {count}", node.name),
            })?;
            let count = count.max(0) as u64;
            node_flops += match cost {
                Cost::FMA(_) => 2 * count,
                Cost::Div(_) => count,
                _ => 0,
            };
        }
        flops += node_flops;
        if let Some(einsum) = node.op_as::<EinSum>()
            && let Some(shape) = matmul_shape(einsum, &facts)
        {
            matmul_flops += node_flops;
            match matmuls.iter_mut().find(|(s, _)| *s == shape) {
                Some((_, n)) => *n += 1,
                None => matmuls.push((shape, 1)),
            }
        }
    }
    matmuls.sort_by_key(|(s, n)| std::cmp::Reverse(s.flops() * *n as u64));
    Ok(NetworkCost { flops, matmul_flops, matmuls })
}

/// The batch, m, k and n of a two-input einsum: axes in both inputs and the output are
/// batch, in both inputs only k, in one input and the output m (first) or n (second).
fn matmul_shape(einsum: &EinSum, facts: &[&TypedFact]) -> Option<MatmulShape> {
    if facts.len() < 2 {
        return None;
    }
    let dim = |input: usize, axis: usize| facts[input].shape.get(axis)?.to_usize().ok();
    let mut shape = MatmulShape { batch: 1, m: 1, k: 1, n: 1 };
    for axis in einsum.axes.iter_all_axes() {
        let (a, b) = (axis.inputs.first()?, axis.inputs.get(1)?);
        let out = !axis.outputs.first()?.is_empty();
        let size = match (a.first(), b.first()) {
            (Some(&i), _) => dim(0, i)?,
            (None, Some(&i)) => dim(1, i)?,
            (None, None) => 1,
        };
        match (!a.is_empty(), !b.is_empty(), out) {
            (true, true, true) => shape.batch *= size,
            (true, true, false) => shape.k *= size,
            (true, false, true) => shape.m *= size,
            (false, true, true) => shape.n *= size,
            _ => {}
        }
    }
    (shape.k > 1).then_some(shape)
}

/// Deterministic inputs for one run of a network with `inputs` (name, shape): values in
/// [-0.5, 0.5), 1 for masks (`*mask*`), so that two engines can be timed and compared on the
/// same numbers.
pub fn bench_inputs(inputs: &[crate::manifest::TensorSpec]) -> Vec<Vec<f32>> {
    inputs
        .iter()
        .enumerate()
        .map(|(i, spec)| {
            let len = spec.shape.iter().product();
            if spec.name.contains("mask") { vec![1.0; len] } else { pseudo_random(len, 11 + i as u32) }
        })
        .collect()
}

/// `len` deterministic values in [-0.5, 0.5) (a multiplicative hash of the index).
fn pseudo_random(len: usize, seed: u32) -> Vec<f32> {
    (0..len)
        .map(|i| {
            ((i as u32).wrapping_mul(2_654_435_761).wrapping_add(seed.wrapping_mul(40_503)) >> 8) as f32 / 16_777_216.0
                - 0.5
        })
        .collect()
}

/// One plain matrix product `[batch, m, k] · [k, n]` (a constant right-hand side, as a
/// network's weights are) planned by tract: the attainable FLOP/s of that shape here.
pub struct MatmulProbe {
    shape: MatmulShape,
    plan: Arc<TypedRunnableModel>,
    input: TValue,
}

impl std::fmt::Debug for MatmulProbe {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MatmulProbe").field("shape", &self.shape).finish()
    }
}

impl MatmulProbe {
    /// Builds and optimises the probe for `shape` (deterministic inputs).
    pub fn new(shape: MatmulShape) -> Result<Self, InferError> {
        let err = model_err("matmul probe");
        let MatmulShape { batch, m, k, n } = shape;
        let values = pseudo_random;
        let mut model = TypedModel::default();
        let a = model.add_source("a", f32::fact([batch, m, k])).map_err(&err)?;
        let weights = Tensor::from_shape(&[k, n], &values(k * n, 7)).map_err(&err)?;
        let b = model.add_const("b", weights).map_err(&err)?;
        let axes = "bmk,kn->bmn".parse().map_err(&err)?;
        let out = model.wire_node("matmul", EinSum::new(axes, f32::datum_type()), &[a, b]).map_err(&err)?;
        model.select_output_outlets(&out).map_err(&err)?;
        let plan = model.into_optimized().map_err(&err)?.into_runnable().map_err(&err)?;
        let input = Tensor::from_shape(&[batch, m, k], &values(batch * m * k, 3)).map_err(&err)?.into();
        Ok(MatmulProbe { shape, plan, input })
    }

    pub fn shape(&self) -> MatmulShape {
        self.shape
    }

    /// Runs the product once; returns the sum of its output (so that it cannot be skipped).
    pub fn run(&self) -> Result<f32, InferError> {
        let out = self.plan.run(tvec![self.input.clone()]).map_err(model_err("matmul probe"))?;
        let view = out[0].to_plain_array_view::<f32>().map_err(model_err("matmul probe"))?;
        Ok(view.iter().sum())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_probe_computes_its_product() {
        let probe = MatmulProbe::new(MatmulShape { batch: 2, m: 3, k: 4, n: 5 }).unwrap();
        assert_eq!(probe.shape().flops(), 2 * 2 * 3 * 4 * 5);
        assert!(probe.run().unwrap().is_finite());
    }
}
