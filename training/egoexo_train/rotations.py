"""6D rotations and SMPL forward kinematics, differentiable, for the position loss.

Conventions exactly as in the Rust core (`egoexo-core`): a 6D rotation is the first two
*columns* of the matrix ``[R00, R10, R20, R01, R11, R21]``, decoded by Gram-Schmidt;
``R_j = R_parent @ local_j`` and ``p_j = p_parent + R_parent @ (rest_j - rest_parent)``.
`tests/test_fk_parity.py` checks this file against the Rust FK on fixtures the Rust tests
write (max error <= 1e-5 m).
"""

import torch

PARENTS = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
NUM_JOINTS = 24
NUM_BODY_JOINTS = 21


def rot6d_to_matrix(x: torch.Tensor) -> torch.Tensor:
    """``[..., 6]`` -> ``[..., 3, 3]`` by Gram-Schmidt on the two stored columns."""
    a1, a2 = x[..., 0:3], x[..., 3:6]
    b1 = torch.nn.functional.normalize(a1, dim=-1, eps=1e-8)
    b2 = torch.nn.functional.normalize(a2 - (b1 * a2).sum(-1, keepdim=True) * b1, dim=-1, eps=1e-8)
    b3 = torch.cross(b1, b2, dim=-1)
    return torch.stack([b1, b2, b3], dim=-1)


def forward_kinematics(rest_joints: torch.Tensor, pose_6d: torch.Tensor) -> torch.Tensor:
    """Joint positions relative to the pelvis joint.

    rest_joints: ``[B, 24, 3]`` (metres); pose_6d: ``[B, T, 132]`` (root orientation then 21
    body rotations). Returns ``[B, T, 24, 3]`` with the pelvis at the origin, in the frame the
    root orientation is expressed in. The hands (22, 23) keep their rest rotation.
    """
    b, t, _ = pose_6d.shape
    rots = rot6d_to_matrix(pose_6d.reshape(b, t, 22, 6))
    offsets = rest_joints[:, 1:] - rest_joints[:, PARENTS[1:]]
    offsets = offsets[:, None].expand(b, t, NUM_JOINTS - 1, 3)
    eye = torch.eye(3, dtype=pose_6d.dtype, device=pose_6d.device).expand(b, t, 3, 3)
    global_rot = [rots[:, :, 0]]
    positions = [torch.zeros(b, t, 3, dtype=pose_6d.dtype, device=pose_6d.device)]
    for j in range(1, NUM_JOINTS):
        parent = PARENTS[j]
        local = rots[:, :, j] if j <= NUM_BODY_JOINTS else eye
        global_rot.append(global_rot[parent] @ local)
        positions.append(positions[parent] + (global_rot[parent] @ offsets[:, :, j - 1, :, None])[..., 0])
    return torch.stack(positions, dim=2)
