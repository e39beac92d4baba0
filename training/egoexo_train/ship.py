"""Export trained networks to ONNX for the Rust engine.

- ``--egonet-only``: just ``egonet.onnx`` from a stage-1 checkpoint (the input of
  ``egoexo synth --shards fusion --egonet``).
- otherwise: one tracking mode's EgoNet, gate and fusion into ``models/<n>pt/`` and its entry in
  ``models/manifest.json`` (other modes' entries are kept).
- a live variant (a fusion checkpoint trained with ``--readout-lookahead L``, no ``--ego``): its
  gate and fusion into ``models/<n>pt-live<L>/`` and an entry with ``"lookahead": L`` that shares
  the offline set's EgoNet (the variant must have been validated on that EgoNet's coarse poses).

Examples:
    python -m egoexo_train.ship --ego runs/ego3/ego.pt --fusion runs/fusion3/fusion.pt --out models
    python -m egoexo_train.ship --fusion runs/fusion3-live0/fusion.pt --out models
"""

import argparse
import json
import subprocess
from pathlib import Path

import torch

from .export import WINDOW, example_inputs, export_model_set, export_one, fusion_networks
from .model import EgoNet, Fusion, Gate


def load(path: Path):
    checkpoint = torch.load(path, map_location="cpu", weights_only=False)
    return checkpoint["state"], checkpoint["config"]


def build_egonet(ego_path: Path) -> tuple:
    state, config = load(ego_path)
    egonet = EgoNet(config["window"], config["egonet_hidden"])
    egonet.load_state_dict(state["egonet"])
    return egonet.eval(), config


def build_gate_fusion(state: dict, config: dict) -> tuple:
    gate = Gate(config["gate_features"], config["gate_hidden"])
    gate.load_state_dict(state["gate"])
    fusion = Fusion(config["window"], config["hidden"], config["heads"], config["spatial_layers"],
                    config["temporal_layers"], dropout=0.0, exo_embed=config.get("exo_embed", "linear"),
                    output_smoothing=config.get("output_smoothing", 0.0),
                    exo_smoothing=config.get("exo_smoothing", 0.0), exo_fade=config.get("exo_fade", False))
    fusion.load_state_dict(state["fusion"])
    return gate.eval(), fusion.eval()


def fusion_provenance(config: dict) -> dict:
    return ({k: config[k] for k in ("steps", "batch", "lr", "seed", "hidden", "heads", "spatial_layers",
                                    "temporal_layers", "gate_hidden", "train_seconds", "trainable_parameters",
                                    "train_windows")}
            | {k: config.get(k) for k in ("velocity_weight", "acceleration_weight", "gate_dropout", "gate_aux_weight",
                                          "dropout", "exo_embed", "output_smoothing", "exo_smoothing", "exo_fade",
                                          "readout_lookahead", "readout_weight")})


def ship_live(state: dict, config: dict, out: Path):
    """Exports a live variant's gate and fusion beside the offline set it shares EgoNet with."""
    lookahead = config["readout_lookahead"]
    tracking = config["tracking"]
    points = 3 if tracking == "three_point" else 1
    manifest_path = out / "manifest.json"
    if not manifest_path.exists():
        raise SystemExit(f"{manifest_path} does not exist: ship the offline {points}-point models first")
    manifest = json.loads(manifest_path.read_text())
    offline = next((s for s in manifest["model_sets"] if s["tracking"] == tracking and s.get("lookahead") is None), None)
    if offline is None:
        raise SystemExit(f"{manifest_path} has no offline {points}-point set whose EgoNet the variant could share")
    if config.get("val_egonet_sha256") != offline["egonet"]["sha256"]:
        raise SystemExit("the live variant was validated on coarse poses from another EgoNet than the shipped "
                         f"{offline['egonet']['file']}: make its validation shards with that file")
    if config["max_observers"] != offline["max_observers"]:
        raise SystemExit("the live variant has a different number of observer slots than the offline set")
    gate, fusion = build_gate_fusion(state, config)
    inputs = example_inputs(config["max_observers"], torch.Generator().manual_seed(0))
    prefix = f"{points}pt-live{lookahead}"
    entry = {k: v for k, v in offline.items() if k not in ("gate", "fusion", "fusion_ego_only")}
    entry.update({"lookahead": lookahead, "hidden_dim": config["hidden"]})
    for name, module, ins, outs in [("gate", gate, ["gate_features"], ["gate"])] + fusion_networks(fusion):
        rel = f"{prefix}/{name}.onnx"
        exported = export_one(module, inputs, ins, outs, out / rel)
        exported.pop("_reference", None)
        entry[name] = {"file": rel, **exported}
    manifest["model_sets"] = [s for s in manifest["model_sets"]
                              if not (s["tracking"] == tracking and s.get("lookahead") == lookahead)] + [entry]
    manifest["model_sets"].sort(key=lambda s: (s["tracking"], s.get("lookahead", -1)))
    manifest["training"][f"{tracking}-live{lookahead}"] = {
        "egonet": f"shared with the offline set ({offline['egonet']['file']})",
        "fusion": fusion_provenance(config),
        "shards": config["shard_index"],
        "commit": git_commit(),
    }
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    sizes = sum(entry[m]["bytes"] for m in ("gate", "fusion"))
    print(f"wrote {out}/{prefix} ({sizes / 1e6:.2f} MB) and {manifest_path}")


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--ego", type=Path, help="stage-1 checkpoint (ego.pt); not for live variants")
    parser.add_argument("--fusion", type=Path, help="stage-2 checkpoint (fusion.pt)")
    parser.add_argument("--egonet-only", type=Path, metavar="FILE", help="write only egonet.onnx here")
    parser.add_argument("--out", type=Path, default=Path("models"))
    args = parser.parse_args()

    if args.fusion is not None and args.ego is None:
        state, config = load(args.fusion)
        if config.get("readout_lookahead") is None:
            parser.error("--ego is required for offline models (only live variants share the shipped EgoNet)")
        ship_live(state, config, args.out)
        return
    if args.ego is None:
        parser.error("--ego is required")
    egonet, ego_config = build_egonet(args.ego)
    if args.egonet_only:
        inputs = example_inputs(1, torch.Generator().manual_seed(0))
        entry = export_one(egonet, inputs, ["ego"], ["root_6d", "body_6d"], args.egonet_only)
        print(f"wrote {args.egonet_only} ({entry['bytes']} bytes, sha256 {entry['sha256']})")
        return
    if args.fusion is None:
        parser.error("--fusion is required unless --egonet-only")

    state, config = load(args.fusion)
    if config.get("readout_lookahead") is not None:
        parser.error("a live variant ships without --ego (it shares the offline set's EgoNet)")
    gate, fusion = build_gate_fusion(state, config)
    points = 3 if config["tracking"] == "three_point" else 1
    if ego_config["tracking"] != config["tracking"]:
        raise SystemExit("the EgoNet and fusion checkpoints are for different tracking modes")
    entry, _ = export_model_set(egonet, gate, fusion, points, config["max_observers"], config["hidden"],
                                args.out, f"{points}pt")
    # Stage 2 trains on cross-fitted coarse poses (fold EgoNets, each predicting clips it never
    # saw); its validation shards come from the EgoNet shipped here.
    if config.get("val_egonet_sha256") != entry["egonet"]["sha256"]:
        raise SystemExit("the fusion network was validated on coarse poses from a different EgoNet export")

    manifest_path = args.out / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.exists() else {
        "format_version": 1, "window": WINDOW, "fps": 30.0, "model_sets": [], "training": {}}
    manifest["model_sets"] = [s for s in manifest["model_sets"]
                              if not (s["tracking"] == entry["tracking"] and s.get("lookahead") is None)] + [entry]
    manifest["model_sets"].sort(key=lambda s: (s["tracking"], s.get("lookahead", -1)))
    manifest["training"][entry["tracking"]] = {
        "data": "CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu) retargeted to SMPL; "
                "simulated wearer devices, observers and 2D keypoints (egoexo-synth)",
        "train_subjects": config["shard_index"]["subjects"],
        "egonet": {k: ego_config[k] for k in ("steps", "batch", "lr", "seed", "egonet_hidden", "train_seconds",
                                               "trainable_parameters", "train_windows")},
        "fusion": fusion_provenance(config),
        "shards": config["shard_index"],
        "commit": git_commit(),
    }
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    sizes = sum(entry[m]["bytes"] for m in ("egonet", "gate", "fusion"))
    print(f"wrote {args.out}/{points}pt ({sizes / 1e6:.2f} MB) and {manifest_path}")


if __name__ == "__main__":
    main()
