"""The networks keep the tensor contract the Rust engine relies on
(crates/egoexo-infer/src/inputs.rs): shapes, the residual on EgoNet's coarse pose, masking."""

import pytest
import torch

from egoexo_train.model import EgoNet, Fusion, Gate


def test_shapes_and_gate_range():
    torch.manual_seed(0)
    ego = torch.randn(2, 96, 60)
    root, body = EgoNet(96, 32)(ego)
    assert root.shape == (2, 96, 6) and body.shape == (2, 96, 126)
    gate = Gate(5, 16)(torch.rand(2, 96, 3, 13, 5))
    assert gate.shape == (2, 96, 3, 13) and (gate >= 0).all() and (gate <= 1).all()


@pytest.mark.parametrize("exo_embed", ["linear", "mlp"])
def test_masked_observers_do_not_change_the_output(exo_embed):
    torch.manual_seed(1)
    fusion = Fusion(96, 32, 4, 1, 1, dropout=0.0, exo_embed=exo_embed).eval()
    ego, egonet = torch.randn(1, 96, 60), torch.randn(1, 96, 132)
    exo = torch.randn(1, 96, 3, 13, 4)
    mask = torch.tensor([1.0, 0.0, 0.0]).expand(1, 96, 3).clone()
    other = exo.clone()
    other[:, :, 1:] = torch.randn_like(other[:, :, 1:]) * 5
    with torch.no_grad():
        a = fusion(ego, egonet, exo, mask)
        b = fusion(ego, egonet, other, mask)
    assert torch.allclose(a[0], b[0], atol=1e-5) and torch.allclose(a[1], b[1], atol=1e-5)
