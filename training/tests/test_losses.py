"""The training losses: zero for a perfect prediction, the temporal terms blind to padded
frames, and the acceleration term larger than the velocity term for frame-to-frame noise
(the jitter it exists to suppress)."""

import torch

from egoexo_train.rotations import forward_kinematics
from egoexo_train.train import HEAD_JOINT, pose_losses, readout_frames

REST = torch.tensor([[0.0, 0.9, 0.0]] + [[0.05 * (j % 3 - 1), 0.9 + 0.03 * j, 0.01 * j] for j in range(1, 24)])


def head_relative(rest, pose):
    pos = forward_kinematics(rest, pose)
    return pos - pos[:, :, HEAD_JOINT:HEAD_JOINT + 1]


def smooth_poses(b=2, t=96):
    """A slowly varying 6D pose sequence (identity plus a small drifting offset)."""
    identity = torch.tensor([1.0, 0.0, 0.0, 0.0, 1.0, 0.0]).repeat(22)
    phase = torch.linspace(0, 1, t)[None, :, None]
    drift = 0.1 * torch.sin(2 * torch.pi * phase + torch.arange(132)[None, None, :])
    return identity + drift.expand(b, t, 132)


def test_perfect_prediction_has_zero_losses():
    target = smooth_poses()
    rest = REST.expand(2, 24, 3)
    mask = torch.ones(2, 96)
    ls = pose_losses(target[..., :6], target[..., 6:], target, head_relative(rest, target), rest, mask)
    for name, value in ls._asdict().items():
        assert value.item() < 1e-6, (name, value.item())


def test_jitter_raises_acceleration_more_than_velocity_and_padding_is_ignored():
    torch.manual_seed(0)
    target = smooth_poses()
    rest = REST.expand(2, 24, 3)
    true_pos = head_relative(rest, target)
    noisy = target.clone()
    noisy[..., 6:] += 0.02 * torch.randn_like(noisy[..., 6:])
    mask = torch.ones(2, 96)
    ls = pose_losses(noisy[..., :6], noisy[..., 6:], target, true_pos, rest, mask)
    assert ls.velocity > 0 and ls.acceleration > 1.5 * ls.velocity

    # Noise only on padded frames (mask 0) changes none of the masked means.
    padded = target.clone()
    padded[:, 60:, 6:] += 0.3 * torch.randn_like(padded[:, 60:, 6:])
    mask[:, 60:] = 0.0
    ls = pose_losses(padded[..., :6], padded[..., 6:], target, true_pos, rest, mask)
    for name, value in ls._asdict().items():
        assert value.item() < 1e-6, (name, value.item())


def test_readout_frames_are_the_live_read_out_frame_and_the_one_before():
    assert readout_frames(96, 0).nonzero().flatten().tolist() == [94, 95]
    assert readout_frames(96, 4).nonzero().flatten().tolist() == [90, 91]
    # As a loss mask it scores only those frames: an error elsewhere costs nothing.
    target = smooth_poses(1)
    rest = REST.expand(1, 24, 3)
    wrong_early = target.clone()
    wrong_early[:, :90] += 0.3
    mask = readout_frames(96, 4)[None]
    ls = pose_losses(wrong_early[..., :6], wrong_early[..., 6:], target, head_relative(rest, target), rest, mask)
    assert ls.position.item() < 1e-6 and ls.velocity.item() < 1e-6
    wrong_late = target.clone()
    wrong_late[:, 91] += 0.3
    ls = pose_losses(wrong_late[..., :6], wrong_late[..., 6:], target, head_relative(rest, target), rest, mask)
    assert ls.position.item() > 1e-3 and ls.velocity.item() > 1e-3
