"""The networks keep the tensor contract the Rust engine relies on
(crates/egoexo-infer/src/inputs.rs): shapes, the residual on EgoNet's coarse pose, masking."""

import pytest
import torch

from egoexo_train.model import (EGO_DIM, EXO_TOKEN_DIM, EgoNet, Fusion, Gate, faded_exo_tracks, gaussian_kernel_matrix,
                                gaussian_smoothing_matrix, gate_weighted_track_smoothing)


def test_shapes_and_gate_range():
    torch.manual_seed(0)
    ego = torch.randn(2, 96, EGO_DIM)
    root, body = EgoNet(96, 32)(ego)
    assert root.shape == (2, 96, 6) and body.shape == (2, 96, 126)
    gate = Gate(5, 16)(torch.rand(2, 96, 3, 13, 5))
    assert gate.shape == (2, 96, 3, 13) and (gate >= 0).all() and (gate <= 1).all()


@pytest.mark.parametrize("exo_embed,fade", [("linear", False), ("mlp", False), ("linear", True)])
def test_masked_observers_do_not_change_the_output(exo_embed, fade):
    torch.manual_seed(1)
    fusion = Fusion(96, 32, 4, 1, 1, dropout=0.0, exo_embed=exo_embed, exo_smoothing=2.0 if fade else 0.0,
                    exo_fade=fade).eval()
    ego, egonet = torch.randn(1, 96, EGO_DIM), torch.randn(1, 96, 132)
    exo = torch.randn(1, 96, 3, 13, EXO_TOKEN_DIM)
    mask = torch.tensor([1.0, 0.0, 0.0]).expand(1, 96, 3).clone()
    other = exo.clone()
    other[:, :, 1:] = torch.randn_like(other[:, :, 1:]) * 5
    with torch.no_grad():
        a = fusion(ego, egonet, exo, mask)
        b = fusion(ego, egonet, other, mask)
    assert torch.allclose(a[0], b[0], atol=1e-5) and torch.allclose(a[1], b[1], atol=1e-5)


def test_fusion_inputs_follow_the_engine_exo_layout():
    # egoexo-infer's `fusion_exo_input` (exo token layout v4): per keypoint, the ray endpoint
    # and the ray offset (zero where the ray is invalid), then the gate; masked observers'
    # gates are zero (the fusion graph weights and scales the rays by the gate).
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
    v = batch["ray_valid"].unsqueeze(-1)
    assert torch.equal(exo[..., 0:3], batch["rays"] * v)
    assert torch.equal(exo[..., 3:6], batch["ray_offsets"] * v)
    assert torch.equal(exo[..., 6:7], gate.unsqueeze(-1))
    assert (exo[:, :, 2, :, 6] == 0).all() and (gate[batch["ray_valid"] == 0] == 0).all()
    assert (exo[..., :6][batch["ray_valid"] == 0] == 0).all()


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
    ego, egonet = torch.randn(1, 96, EGO_DIM), torch.randn(1, 96, 132)
    exo, mask = torch.randn(1, 96, 2, 13, EXO_TOKEN_DIM), torch.ones(1, 96, 2)
    with torch.no_grad():
        root, body = plain(ego, egonet, exo, mask)
        root_s, body_s = smoothed(ego, egonet, exo, mask)
    s = gaussian_smoothing_matrix(96, 1.0)
    assert torch.allclose(root_s, s @ root, atol=1e-5) and torch.allclose(body_s, s @ body, atol=1e-5)
    assert jerk(body_s) < 0.5 * jerk(body)


def test_gate_weighted_track_smoothing_low_passes_detections_and_drops_rejected_ones():
    kernel = gaussian_kernel_matrix(96, 2.0)
    assert (kernel[50] > 0).sum() == 13  # truncated at 3 sigma: 6 frames either side
    torch.manual_seed(5)
    t = torch.arange(96, dtype=torch.float32)
    # Keypoint 0: a straight line with ±2 cm flicker; a 10-frame gap; one outlier at frame 70.
    truth = torch.stack([0.01 * t, 0.5 - 0.002 * t, torch.full_like(t, 1.2)], dim=-1)
    track = truth + 0.02 * torch.tensor([1.0, -1.0, 0.5]) * torch.where(t % 2 == 0, 1.0, -1.0).unsqueeze(-1)
    track[70] += torch.tensor([0.4, -0.3, 0.2])
    detected = ((t < 40) | (t >= 50)).float()
    values = torch.zeros(1, 96, 1, 2, 3)
    values[0, :, 0, 0] = track * detected.unsqueeze(-1)
    values[0, :, 0, 1] = torch.randn(3)  # keypoint 1: a constant
    gate = torch.ones(1, 96, 1, 2, 1)
    gate[0, :, 0, 0, 0] = detected
    plain = gate_weighted_track_smoothing(kernel, values, gate)
    assert torch.allclose(plain[0, :, 0, 1], values[0, :, 0, 1], atol=1e-6)  # constants kept
    inner = [f for f in range(8, 88) if not 34 <= f < 56 and not 63 <= f < 78]
    assert (plain[0, inner, 0, 0] - truth[inner]).abs().max() < 2e-3  # flicker removed, line kept
    assert ((plain * gate)[0, 40:50, 0, 0] == 0).all()  # gated by 0, the gaps stay empty in the token
    assert (plain[0, 68, 0, 0] - truth[68]).norm() > 0.04  # the outlier leaks into its neighbours
    gate[0, 70, 0, 0, 0] = 0.0  # ... unless the gate rejects it
    gated = gate_weighted_track_smoothing(kernel, values, gate)
    # (within the flicker that no longer cancels around the missing frame)
    assert (gated[0, 64:77, 0, 0] - truth[64:77]).norm(dim=-1).max() < 0.01
    # The valid-masked low-pass is the gate-weighted one with the gate at the validity mask,
    # and scaling every gate by the same factor changes nothing.
    assert torch.allclose(gate_weighted_track_smoothing(kernel, values, 0.3 * gate), gated, atol=1e-6)
    with pytest.raises(ValueError):
        gaussian_kernel_matrix(96, 0.0)


def test_faded_exo_tracks_ramp_rays_in_and_out_and_bridge_missed_frames():
    kernel = gaussian_kernel_matrix(96, 2.0)
    t = torch.arange(96)
    # Observer 0: keypoint 0 detected from frame 40 on at a constant place, the whole observer
    # missed at frame 60. Observer 1: detections everywhere, but masked (dropped) throughout.
    rays = torch.zeros(1, 96, 2, 2, 6)
    gate = torch.zeros(1, 96, 2, 2, 1)
    mask = torch.zeros(1, 96, 2)
    seen = (t >= 40) & (t != 60)
    rays[0, seen, 0, 0] = torch.tensor([0.1, 0.2, 0.3, 0.0, 0.01, 0.0])
    gate[0, seen, 0, 0] = 0.9
    mask[0, seen, 0] = 1.0
    rays[0, :, 1] = torch.randn(96, 2, 6)
    gate[0, :, 1] = 1.0
    smoothed, faded, present = faded_exo_tracks(kernel, rays, gate, mask)
    g = faded[0, :, 0, 0, 0]
    # The gate ramps up over the 6 frames either side of the first detection instead of stepping ...
    assert (g[:34] == 0).all() and (g[34:47].diff() > 0).all() and torch.allclose(g[46:54], torch.tensor(0.9))
    assert 0.3 < g[40] < 0.6
    # ... dips at the missed frame without vanishing, and the observer stays present there.
    assert 0.7 < g[60] < 0.9 and present[0, 60, 0] == 1
    assert (present[0, :34, 0] == 0).all() and (present[0, 40:, 0] == 1).all()
    # The constant ray is kept wherever it has weight, including the missed frame.
    assert torch.allclose(smoothed[0, 34:, 0, 0], rays[0, 50, 0, 0].expand(62, 6), atol=1e-6)
    # A masked observer stays absent however confident its gates, and a keypoint never
    # detected stays empty.
    assert (present[0, :, 1] == 0).all() and (faded[0, :, 1] == 0).all()
    assert (faded[0, :, 0, 1] == 0).all()


def test_fade_needs_the_exo_low_pass():
    with pytest.raises(ValueError):
        Fusion(96, 32, 4, 1, 1, exo_fade=True)
