"""Training code for egoexo's networks (EgoNet, gate, fusion).

Python only fits networks: every input feature, ray, mask and target is computed by the Rust
core and read from the shards `egoexo synth --shards` writes. The one piece of geometry here
is differentiable SMPL forward kinematics for the position loss, checked against the Rust FK
by a parity test (`tests/test_fk_parity.py`).
"""
