//! FLOP counts of the networks and the matrix-product probe.

use crate::common::*;
use egoexo_infer::cost::{MatmulProbe, MatmulShape, network_cost};
use egoexo_infer::manifest::ModelFile;

fn cost_of(file: &ModelFile) -> egoexo_infer::cost::NetworkCost {
    let bytes = std::fs::read(fixture_dir().join(&file.file)).unwrap();
    let shapes: Vec<Vec<usize>> = file.inputs.iter().map(|i| i.shape.clone()).collect();
    network_cost(&file.file, &bytes, &shapes).unwrap()
}

#[test]
fn every_network_costs_its_matrix_products_and_a_little_more() {
    let manifest = fixture_manifest();
    for set in &manifest.model_sets {
        for file in [&set.egonet, &set.gate, &set.fusion] {
            let cost = cost_of(file);
            let products: u64 = cost.matmuls.iter().map(|(s, n)| s.flops() * *n as u64).sum();
            assert_eq!(cost.matmul_flops, products, "{}", file.file);
            assert!(cost.matmul_flops > 0 && cost.matmul_flops <= cost.flops, "{}: {cost:?}", file.file);
            // Products dominate a transformer's arithmetic; elementwise ops are the rest.
            assert!(cost.matmul_flops as f64 > 0.5 * cost.flops as f64, "{}: {cost:?}", file.file);
            // Sorted by total FLOPs, and every product is over the window's 96 frames.
            let totals: Vec<u64> = cost.matmuls.iter().map(|(s, n)| s.flops() * *n as u64).collect();
            assert!(totals.windows(2).all(|w| w[0] >= w[1]), "{totals:?}");
            let dominant = cost.dominant_matmul().unwrap();
            assert_eq!((dominant.batch * dominant.m) % 96, 0, "{}: {dominant:?}", file.file);
        }
    }
}

#[test]
fn the_probe_runs_a_product_of_the_shape_it_was_given() {
    let shape = MatmulShape { batch: 1, m: 96, k: 32, n: 64 };
    let probe = MatmulProbe::new(shape).unwrap();
    assert_eq!(probe.shape(), shape);
    assert_eq!(shape.flops(), 2 * 96 * 32 * 64);
    let sum = probe.run().unwrap();
    assert!(sum.is_finite());
    assert_eq!(sum, probe.run().unwrap(), "deterministic inputs");
}
