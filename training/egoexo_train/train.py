"""Training of EgoNet (stage 1) and the gate + fusion networks (stage 2, EgoNet frozen).

Reads the shards `egoexo synth --shards {ego,fusion}` writes (every input computed by the
Rust core); the only computation here besides the networks is the differentiable FK of the
position loss (`rotations.py`, parity-tested against Rust).

Losses (paper § Training): L1 on the root orientation 6D (x 0.02), on the 21 body rotations
6D (x 1) and on FK joint positions (x 1, metres). Positions are taken relative to the head
joint, the joint the engine anchors to the tracked head device. Stage 2 adds two things the
small simulated dataset needs, both documented in the model card:
- observer dropout (all observers masked for 15 % of windows, each observer for 15 %), so the
  same network runs ego-only;
- gate dropout (the gate replaced by the plain validity mask for 25 % of windows), so the
  ungated ablation is in-distribution, and optionally an auxiliary BCE (`--gate-aux-weight`,
  0.1 by default, 0 for the shipped models) pulling the gate towards 1 where the ray passes
  within 0.15 m of the true joint (the shards' `ray_error` label) and towards 0 elsewhere.
The fusion graph can low-pass its exo input over time (`--exo-smoothing`, `--exo-fade`) and
its output (`--output-smoothing`); see `model.py`.

Live variants (`--readout-lookahead L`): live reconstruction reads each window out at frame
`T - 1 - L`, L frames before its newest frame (the offline models are read out near the centre,
with 48 frames of context on each side). Such a model is trained with the same losses over the
whole window plus, weighted by `--readout-weight`, the same losses (velocity included) on the
read-out frame and the frame before it, so the network learns to use one-sided context there.

Example (the exact commands are in training/README.md):
    python -m egoexo_train.train --stage ego --shards data/ego3 --val data/val-ego3 --out runs/ego3 --steps 3000
"""

import argparse
import csv
import json
import math
import time
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from .model import EGO_LAYOUT_VERSION, EgoNet, Fusion, Gate
from .rotations import forward_kinematics

HEAD_JOINT = 15
ROOT_WEIGHT, BODY_WEIGHT, POSITION_WEIGHT, GATE_AUX_WEIGHT = 0.02, 1.0, 1.0, 0.1
#: Fraction of stage-2 training windows whose gate is replaced by the validity mask.
GATE_DROPOUT = 0.25

EGO_KEYS = ["ego", "target", "frame_mask", "rest_joints"]
BATCH_KEYS_EXTRA = ["target_positions"]
#: The shard format this code reads (`SHARD_FORMAT_VERSION` in `egoexo-dataset`).
SHARD_FORMAT_VERSION = 5
FUSION_KEYS = EGO_KEYS + ["egonet", "rays", "ray_offsets", "ray_valid", "gate_features", "observer_mask", "occluded",
                          "ray_error"]
#: A ray counts as accurate for the gate's auxiliary loss when it passes this close (metres)
#: to the true keypoint (the shards' `ray_error`, computed by the Rust core).
ACCURATE_RAY_M = 0.15


def parse_fold(text: str) -> tuple:
    k, n = (int(x) for x in text.split("/"))
    if n < 2 or not 0 <= k < n:
        raise argparse.ArgumentTypeError(f"expected K/N with N >= 2 and 0 <= K < N, got {text!r}")
    return k, n


def load_shards(folders, keys: list, exclude_fold=None) -> dict:
    """All shards of one or more folders, concatenated, as float32 torch tensors. With
    `exclude_fold = (k, n)` the windows of library clips `c` with `c mod n == k` are dropped
    (the same folds as `egoexo synth --fold`). The index returned is the first folder's, with
    the EgoNet hashes of all folders under "egonet_sha256s"."""
    folders = [folders] if isinstance(folders, Path) else list(folders)
    indices = [json.loads((f / "index.json").read_text()) for f in folders]
    for folder, index in zip(folders, indices):
        if index.get("format_version") != SHARD_FORMAT_VERSION:
            raise SystemExit(f"{folder / 'index.json'}: format_version {index.get('format_version')}, expected "
                             f"{SHARD_FORMAT_VERSION}: remake the shards with this build's `egoexo synth --shards`")
        if index.get("ego_feature_layout_version") != EGO_LAYOUT_VERSION:
            raise SystemExit(f"{folder / 'index.json'}: ego feature layout v{index.get('ego_feature_layout_version')}, "
                             f"these networks read v{EGO_LAYOUT_VERSION}: remake the shards with this build")
    parts = {k: [] for k in keys}
    for folder, index in zip(folders, indices):
        for entry in index["shards"]:
            with np.load(folder / entry["file"]) as npz:
                keep = slice(None)
                if exclude_fold is not None:
                    keep = npz["clip"] % exclude_fold[1] != exclude_fold[0]
                for k in keys:
                    parts[k].append(npz[k][keep].astype(np.float32))
    for key in ("window", "pose_dim", "ego_feature_layout_version", "gate_feature_layout_version", "stage"):
        if len({json.dumps(i.get(key)) for i in indices}) != 1:
            raise SystemExit(f"shard folders {[str(f) for f in folders]} disagree on {key}")
    index = dict(indices[0])
    index["egonet_sha256s"] = sorted({i["egonet_sha256"] for i in indices if i.get("egonet_sha256")})
    index["subjects"] = sorted({s for i in indices for s in i["subjects"]})
    index["windows"] = sum(i["windows"] for i in indices)
    index["frames_simulated"] = sum(i["frames_simulated"] for i in indices)
    data = {k: torch.from_numpy(np.concatenate(v)) for k, v in parts.items()}
    # The targets' head-relative joint positions never change: compute them once.
    with torch.no_grad():
        chunks = []
        for i in range(0, data["target"].shape[0], 256):
            pos = forward_kinematics(data["rest_joints"][i:i + 256], data["target"][i:i + 256])
            chunks.append(pos - pos[:, :, HEAD_JOINT:HEAD_JOINT + 1])
        data["target_positions"] = torch.cat(chunks)
    data["index"] = index
    return data


class PoseLosses(NamedTuple):
    """Masked means over a batch of windows; positions head-relative, in metres."""

    root: torch.Tensor
    body: torch.Tensor
    position: torch.Tensor
    mpjpe: torch.Tensor
    #: L1 on frame-to-frame joint displacements (m / frame).
    velocity: torch.Tensor
    #: L1 on second differences of joint positions (m / frame^2).
    acceleration: torch.Tensor


def pose_losses(pred_root, pred_body, target, true_pos, rest, mask) -> PoseLosses:
    """Root and body 6D L1, FK position L1, MPJPE, and the velocity and acceleration L1 of the
    predicted joint trajectories against the targets'; `true_pos` are the targets' head-relative
    joint positions, `mask [B,T]` the real frames."""
    w = mask.unsqueeze(-1)
    denom = mask.sum().clamp(min=1.0)
    root = ((pred_root - target[..., :6]).abs() * w).sum() / (denom * 6)
    body = ((pred_body - target[..., 6:]).abs() * w).sum() / (denom * 126)
    pred_pos = forward_kinematics(rest, torch.cat([pred_root, pred_body], dim=-1))
    pred_pos = pred_pos - pred_pos[:, :, HEAD_JOINT:HEAD_JOINT + 1]
    err = (pred_pos - true_pos).abs().mean(dim=(-1, -2))
    position = (err * mask).sum() / denom
    mpjpe = (((pred_pos - true_pos) ** 2).sum(-1).sqrt().mean(-1) * mask).sum() / denom
    pair = mask[:, 1:] * mask[:, :-1]
    pred_vel, true_vel = pred_pos[:, 1:] - pred_pos[:, :-1], true_pos[:, 1:] - true_pos[:, :-1]
    dv = (pred_vel - true_vel).abs().mean(dim=(-1, -2))
    velocity = (dv * pair).sum() / pair.sum().clamp(min=1.0)
    triple = pair[:, 1:] * pair[:, :-1]
    da = ((pred_vel[:, 1:] - pred_vel[:, :-1]) - (true_vel[:, 1:] - true_vel[:, :-1])).abs().mean(dim=(-1, -2))
    acceleration = (da * triple).sum() / triple.sum().clamp(min=1.0)
    return PoseLosses(root, body, position, mpjpe, velocity, acceleration)


def readout_frames(window: int, lookahead: int) -> torch.Tensor:
    """``[window]``: 1 at the frame live use reads out with `lookahead` (``window - 1 - lookahead``)
    and at the frame before it (so the read-out losses include its velocity), 0 elsewhere."""
    mask = torch.zeros(window)
    mask[window - 2 - lookahead:window - lookahead] = 1.0
    return mask


def fusion_inputs(batch, gate_net, train: bool, generator: torch.Generator,
                  gate_dropout: float = GATE_DROPOUT):
    """Gate, observer dropout and gate dropout (the gate replaced by the validity mask for a
    `gate_dropout` fraction of training windows) -> (exo tokens, observer mask, gate values)."""
    valid = batch["ray_valid"]
    gate = gate_net(batch["gate_features"]) * valid
    mask = batch["observer_mask"].clone()
    if train:
        b, t, n = mask.shape
        drop_all = torch.rand(b, 1, 1, generator=generator) < 0.15
        drop_one = torch.rand(b, 1, n, generator=generator) < 0.15
        mask = mask * (~(drop_all | drop_one)).float()
        ungated = (torch.rand(b, 1, 1, 1, generator=generator) < gate_dropout).float()
        gate = ungated * valid + (1.0 - ungated) * gate
    gate = gate * mask.unsqueeze(-1)
    v = valid.unsqueeze(-1)
    exo = torch.cat([batch["rays"] * v, batch["ray_offsets"] * v, gate.unsqueeze(-1)], dim=-1)
    return exo, mask, gate


def gate_aux_loss(gate_net, batch):
    """BCE pulling the gate towards 1 for rays that pass within `ACCURATE_RAY_M` of the true
    keypoint and towards 0 for the others (valid rays only)."""
    valid = batch["ray_valid"]
    target = valid * (batch["ray_error"] < ACCURATE_RAY_M).float()
    g = gate_net(batch["gate_features"]).clamp(1e-5, 1 - 1e-5)
    bce = -(target * g.log() + (1 - target) * (1 - g).log())
    return (bce * valid).sum() / valid.sum().clamp(min=1.0)


def batches(n: int, batch_size: int, generator: torch.Generator):
    while True:
        order = torch.randperm(n, generator=generator)
        for i in range(0, n - batch_size + 1, batch_size):
            yield order[i:i + batch_size]


def take(data: dict, idx, keys) -> dict:
    return {k: data[k][idx] for k in keys}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--stage", choices=["ego", "fusion"], required=True)
    parser.add_argument("--shards", type=Path, nargs="+", required=True,
                        help="shard folders (several: e.g. the cross-fitted folds of stage 2)")
    parser.add_argument("--exclude-fold", type=parse_fold, default=None,
                        help="K/N: drop the windows of clips in fold K of N (a cross-fitting EgoNet)")
    parser.add_argument("--val", type=Path, required=True)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--egonet-hidden", type=int, default=256)
    parser.add_argument("--hidden", type=int, default=128, help="fusion width d")
    parser.add_argument("--heads", type=int, default=4)
    parser.add_argument("--spatial-layers", type=int, default=2)
    parser.add_argument("--temporal-layers", type=int, default=3)
    parser.add_argument("--gate-hidden", type=int, default=128)
    parser.add_argument("--dropout", type=float, default=0.1, help="fusion transformer dropout")
    parser.add_argument("--exo-embed", choices=["linear", "mlp"], default="linear",
                        help="exo token projection: linear (the paper) or a two-layer MLP")
    parser.add_argument("--output-smoothing", type=float, default=0.0, metavar="SIGMA",
                        help="fusion: a fixed Gaussian low-pass over time on the outputs, SIGMA frames (0 = off)")
    parser.add_argument("--exo-smoothing", type=float, default=0.0, metavar="SIGMA",
                        help="fusion: a gate-weighted Gaussian low-pass over time on each keypoint's rays, SIGMA frames (0 = off)")
    parser.add_argument("--exo-fade", action="store_true",
                        help="fusion (with --exo-smoothing): low-pass the gate too and derive each observer's presence "
                             "from it, so rays and observers fade in and out")
    parser.add_argument("--steps", type=int, default=3000)
    parser.add_argument("--batch", type=int, default=32)
    parser.add_argument("--lr", type=float, default=1e-3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--eval-every", type=int, default=200)
    parser.add_argument("--velocity-weight", type=float, default=0.0,
                        help="weight of an L1 loss on frame-to-frame joint displacements (not in the paper; 0 = off)")
    parser.add_argument("--acceleration-weight", type=float, default=0.0,
                        help="weight of an L1 loss on second differences of joint positions (not in the paper; 0 = off)")
    parser.add_argument("--gate-aux-weight", type=float, default=GATE_AUX_WEIGHT,
                        help="stage 2: weight of the BCE pulling the gate towards 'the ray passes within "
                             f"{ACCURATE_RAY_M} m of the true keypoint'")
    parser.add_argument("--gate-dropout", type=float, default=GATE_DROPOUT,
                        help="stage 2: fraction of training windows whose gate is replaced by the validity mask")
    parser.add_argument("--readout-lookahead", type=int, default=None, metavar="L",
                        help="stage 2, live variants: add the losses on the read-out frame T-1-L (and the frame "
                             "before it, for the velocity)")
    parser.add_argument("--readout-weight", type=float, default=1.0,
                        help="weight of the read-out losses relative to the whole-window losses")
    args = parser.parse_args()
    if args.readout_lookahead is not None and args.stage != "fusion":
        parser.error("--readout-lookahead trains live fusion variants (--stage fusion)")

    torch.manual_seed(args.seed)
    torch.set_num_threads(args.threads)
    generator = torch.Generator().manual_seed(args.seed)
    keys = EGO_KEYS if args.stage == "ego" else FUSION_KEYS
    train_data = load_shards(args.shards, keys, args.exclude_fold)
    val_data = load_shards(args.val, keys)
    index = train_data["index"]
    if args.stage == "fusion" and not index["egonet_sha256s"]:
        raise SystemExit("fusion shards carry no EgoNet hash: make them with `egoexo synth --shards fusion --egonet`")
    window = index["window"]
    n_train = train_data["ego"].shape[0]
    print(f"{args.stage}: {n_train} training windows, {val_data['ego'].shape[0]} validation windows, "
          f"tracking {index['options']['tracking']}")

    modules = {}
    if args.stage == "ego":
        egonet = EgoNet(window, args.egonet_hidden)
        modules["egonet"] = egonet
        params = list(egonet.parameters())
    else:
        n = train_data["observer_mask"].shape[-1]
        features = train_data["gate_features"].shape[-1]
        gate_net = Gate(features, args.gate_hidden)
        fusion = Fusion(window, args.hidden, args.heads, args.spatial_layers, args.temporal_layers,
                        dropout=args.dropout, exo_embed=args.exo_embed, output_smoothing=args.output_smoothing,
                        exo_smoothing=args.exo_smoothing, exo_fade=args.exo_fade)
        modules.update({"gate": gate_net, "fusion": fusion})
        params = list(gate_net.parameters()) + list(fusion.parameters())
    total_params = sum(p.numel() for p in params)
    optimizer = torch.optim.AdamW(params, lr=args.lr, weight_decay=1e-4)
    schedule = torch.optim.lr_scheduler.LambdaLR(
        optimizer, lambda s: min(1.0, (s + 1) / 200) * 0.5 * (1 + math.cos(math.pi * min(s, args.steps) / args.steps)))

    def forward(batch, train):
        if args.stage == "ego":
            return modules["egonet"](batch["ego"]), None
        exo, mask, gate = fusion_inputs(batch, modules["gate"], train, generator, args.gate_dropout)
        return modules["fusion"](batch["ego"], batch["egonet"], exo, mask), gate

    readout = None
    if args.readout_lookahead is not None:
        if not 0 <= args.readout_lookahead < window - 1:
            parser.error(f"--readout-lookahead must be in 0..{window - 2}")
        readout = readout_frames(window, args.readout_lookahead)

    def losses(root, body, batch, mask):
        ls = pose_losses(root, body, batch["target"], batch["target_positions"], batch["rest_joints"], mask)
        return ls, ROOT_WEIGHT * ls.root + BODY_WEIGHT * ls.body + POSITION_WEIGHT * ls.position

    def evaluate():
        """Validation loss, root L1, body L1 and MPJPE over whole windows, and the MPJPE of the
        read-out frames (NaN without `--readout-lookahead`)."""
        for m in modules.values():
            m.eval()
        totals, readout_totals = np.zeros(5), np.zeros(2)
        with torch.no_grad():
            n_val = val_data["ego"].shape[0]
            for i in range(0, n_val, 64):
                batch = take(val_data, slice(i, i + 64), keys + BATCH_KEYS_EXTRA)
                (root, body), _ = forward(batch, False)
                ls, loss = losses(root, body, batch, batch["frame_mask"])
                w = batch["frame_mask"].sum().item()
                totals += np.array([loss.item(), ls.root.item(), ls.body.item(), ls.mpjpe.item(), 1.0]) * w
                if readout is not None:
                    mask = batch["frame_mask"] * readout
                    readout_totals += np.array([losses(root, body, batch, mask)[0].mpjpe.item(), 1.0]) * mask.sum().item()
        for m in modules.values():
            m.train()
        readout_mpjpe = readout_totals[0] / readout_totals[1] if readout_totals[1] > 0 else float("nan")
        return np.append(totals[:4] / max(totals[4], 1.0), readout_mpjpe)

    args.out.mkdir(parents=True, exist_ok=True)
    log = open(args.out / "curve.csv", "w", newline="")
    writer = csv.writer(log)
    writer.writerow(["step", "seconds", "train_loss", "val_loss", "val_root_l1", "val_body_l1", "val_head_relative_mpjpe_cm",
                     "lr", "val_readout_mpjpe_cm"])
    start = time.time()
    running = []
    stream = batches(n_train, args.batch, generator)
    for step in range(1, args.steps + 1):
        batch = take(train_data, next(stream), keys + BATCH_KEYS_EXTRA)
        (root, body), _ = forward(batch, True)
        ls, loss = losses(root, body, batch, batch["frame_mask"])
        loss = loss + args.velocity_weight * ls.velocity + args.acceleration_weight * ls.acceleration
        if readout is not None:
            ls_r, loss_r = losses(root, body, batch, batch["frame_mask"] * readout)
            loss = loss + args.readout_weight * (loss_r + args.velocity_weight * ls_r.velocity)
        if args.stage == "fusion" and args.gate_aux_weight > 0:
            loss = loss + args.gate_aux_weight * gate_aux_loss(modules["gate"], batch)
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, 1.0)
        optimizer.step()
        schedule.step()
        running.append(loss.item())
        if step % args.eval_every == 0 or step == args.steps:
            val = evaluate()
            elapsed = time.time() - start
            writer.writerow([step, f"{elapsed:.1f}", f"{np.mean(running):.5f}", f"{val[0]:.5f}", f"{val[1]:.5f}",
                             f"{val[2]:.5f}", f"{100 * val[3]:.2f}", f"{schedule.get_last_lr()[0]:.2e}",
                             f"{100 * val[4]:.2f}"])
            log.flush()
            readout_text = f", read-out frame {100 * val[4]:.2f} cm" if readout is not None else ""
            print(f"step {step:5d} {elapsed:7.0f}s train {np.mean(running):.4f} val {val[0]:.4f} "
                  f"head-relative MPJPE {100 * val[3]:.2f} cm{readout_text}", flush=True)
            running = []
    seconds = time.time() - start
    state = {name: m.state_dict() for name, m in modules.items()}
    config = {k: v for k, v in vars(args).items() if not isinstance(v, Path)}
    config["shards"] = [str(f) for f in args.shards]
    config.update({"window": window, "tracking": index["options"]["tracking"],
                   "max_observers": index["options"]["max_observers"],
                   "gate_features": index["gate_feature_dim"], "trainable_parameters": total_params,
                   "train_seconds": seconds, "train_windows": n_train, "shard_index": {k: index[k] for k in (
                       "subjects", "windows", "frames_simulated", "options", "egonet_sha256s") if k in index},
                   "val_egonet_sha256": val_data["index"].get("egonet_sha256")})
    torch.save({"state": state, "config": config}, args.out / f"{args.stage}.pt")
    (args.out / "config.json").write_text(json.dumps(config, indent=2) + "\n")
    print(f"trained {total_params} parameters in {seconds / 60:.1f} min; saved {args.out / (args.stage + '.pt')}")


if __name__ == "__main__":
    main()
