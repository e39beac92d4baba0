"""The PyTorch FK of the position loss equals the Rust core's FK (fixture written by
crates/egoexo-core/tests/core_tests/fk_parity_fixture.rs), to 1e-5 m."""

import json
from pathlib import Path

import torch

from egoexo_train.rotations import forward_kinematics

FIXTURE = Path(__file__).parent / "fixtures" / "fk_parity.json"


def test_torch_fk_matches_rust_fk():
    data = json.loads(FIXTURE.read_text())
    worst = 0.0
    for case in data["cases"]:
        rest = torch.tensor(case["rest_joints"], dtype=torch.float32).reshape(1, 24, 3)
        pose = torch.tensor([f["pose_6d"] for f in case["frames"]], dtype=torch.float32).reshape(1, -1, 132)
        expected = torch.tensor([f["positions"] for f in case["frames"]], dtype=torch.float32).reshape(1, -1, 24, 3)
        got = forward_kinematics(rest, pose)
        worst = max(worst, (got - expected).abs().max().item())
    assert worst <= 1e-5, f"max |torch FK - Rust FK| = {worst} m"


def test_fk_parity_fails_when_the_6d_convention_is_broken():
    # Reading the 6D as rows instead of columns must break parity (the test can fail).
    data = json.loads(FIXTURE.read_text())
    case = data["cases"][0]
    rest = torch.tensor(case["rest_joints"]).reshape(1, 24, 3)
    pose = torch.tensor([f["pose_6d"] for f in case["frames"]]).reshape(1, -1, 22, 2, 3).transpose(-1, -2).reshape(1, -1, 132)
    expected = torch.tensor([f["positions"] for f in case["frames"]]).reshape(1, -1, 24, 3)
    assert (forward_kinematics(rest, pose) - expected).abs().max().item() > 1e-2
