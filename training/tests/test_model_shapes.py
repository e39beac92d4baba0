"""The networks keep the tensor contract the Rust engine relies on
(crates/egoexo-infer/src/inputs.rs): shapes, the residual on EgoNet's coarse pose, masking."""

import pytest
import torch

from egoexo_train.model import EXO_TOKEN_DIM, EgoNet, Fusion, Gate, gaussian_smoothing_matrix


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
    exo = torch.randn(1, 96, 3, 13, EXO_TOKEN_DIM)
    mask = torch.tensor([1.0, 0.0, 0.0]).expand(1, 96, 3).clone()
    other = exo.clone()
    other[:, :, 1:] = torch.randn_like(other[:, :, 1:]) * 5
    with torch.no_grad():
        a = fusion(ego, egonet, exo, mask)
        b = fusion(ego, egonet, other, mask)
    assert torch.allclose(a[0], b[0], atol=1e-5) and torch.allclose(a[1], b[1], atol=1e-5)


def test_fusion_inputs_follow_the_engine_exo_layout():
    # egoexo-infer's `gated_exo` (exo token layout v3): per keypoint, the ray endpoint and the
    # ray offset each scaled by the gate, then the gate; masked observers are all zero.
    from egoexo_train.train import fusion_inputs

    torch.manual_seed(2)
    b, t, n, k = 1, 96, 3, 13
    batch = {
        "rays": torch.randn(b, t, n, k, 3), "ray_offsets": torch.randn(b, t, n, k, 3),
        "ray_valid": (torch.rand(b, t, n, k) > 0.2).float(), "gate_features": torch.rand(b, t, n, k, 5),
        "observer_mask": torch.tensor([1.0, 1.0, 0.0]).expand(b, t, n).clone(),
    }
    exo, mask, gate = fusion_inputs(batch, Gate(5, 16), False, torch.Generator().manual_seed(0))
    assert exo.shape == (b, t, n, k, EXO_TOKEN_DIM) == (b, t, n, k, 7)
    g = gate.unsqueeze(-1)
    assert torch.equal(exo[..., 0:3], batch["rays"] * g)
    assert torch.equal(exo[..., 3:6], batch["ray_offsets"] * g)
    assert torch.equal(exo[..., 6:7], g)
    assert (exo[:, :, 2] == 0).all() and (gate[batch["ray_valid"] == 0] == 0).all()


def jerk(x: torch.Tensor) -> torch.Tensor:
    """Mean magnitude of third differences over time (dim -2)."""
    d = x[..., 3:, :] - 3 * x[..., 2:-1, :] + 3 * x[..., 1:-2, :] - x[..., :-3, :]
    return d.abs().mean()


def test_smoothing_matrix_keeps_constants_and_filters_flicker():
    assert torch.equal(gaussian_smoothing_matrix(96, 0.0), torch.eye(96))
    s = gaussian_smoothing_matrix(96, 1.0)
    assert torch.allclose(s.sum(dim=1), torch.ones(96))
    assert torch.allclose(s[10:86, 10:86], s[10:86, 10:86].T)  # symmetric away from the edges
    constant = torch.full((96, 4), 0.7)
    assert torch.allclose(s @ constant, constant, atol=1e-6)
    # A straight line is kept inside the window (the kernel is symmetric there).
    line = torch.arange(96, dtype=torch.float32).unsqueeze(1)
    assert torch.allclose((s @ line)[3:93], line[3:93], atol=1e-4)
    torch.manual_seed(3)
    slow = torch.sin(torch.linspace(0, 6.0, 96)).unsqueeze(1)
    noisy = slow + 0.05 * torch.randn(96, 1)
    assert jerk(s @ noisy) < 0.2 * jerk(noisy)
    assert (s @ noisy - slow).abs().mean() < (noisy - slow).abs().mean()
    with pytest.raises(ValueError):
        gaussian_smoothing_matrix(96, -1.0)


def test_fusion_output_smoothing_is_the_fixed_low_pass_of_the_unsmoothed_network():
    torch.manual_seed(4)
    plain = Fusion(96, 32, 4, 1, 1, dropout=0.0).eval()
    smoothed = Fusion(96, 32, 4, 1, 1, dropout=0.0, output_smoothing=1.0).eval()
    smoothed.load_state_dict(plain.state_dict())  # the low-pass has no weights of its own
    ego, egonet = torch.randn(1, 96, 60), torch.randn(1, 96, 132)
    exo, mask = torch.randn(1, 96, 2, 13, EXO_TOKEN_DIM), torch.ones(1, 96, 2)
    with torch.no_grad():
        root, body = plain(ego, egonet, exo, mask)
        root_s, body_s = smoothed(ego, egonet, exo, mask)
    s = gaussian_smoothing_matrix(96, 1.0)
    assert torch.allclose(root_s, s @ root, atol=1e-5) and torch.allclose(body_s, s @ body, atol=1e-5)
    assert jerk(body_s) < 0.5 * jerk(body)
