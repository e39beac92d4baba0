"""ONNX export of the three networks and the manifest entry that describes them.

Settings from shared/notes/toolchain.md: opset 17, the TorchScript exporter
(``dynamo=False``), batch 1 and T = 96 fixed. `python -m egoexo_train.export --random-init`
writes a small untrained set with reference inputs/outputs (the engine's test fixture).
"""

import argparse
import hashlib
import json
import warnings
from pathlib import Path

import numpy as np
import torch

from .model import (EGO_DIM, EGO_LAYOUT_VERSION, EXO_TOKEN_DIM, EXO_TOKEN_LAYOUT_VERSION, K, POSE_DIM, EgoNet, Fusion,
                    FusionEgoOnly, Gate)

WINDOW = 96
OPSET = 17
GATE_LAYOUT_VERSION = 2
GATE_FEATURE_DIM = 6


def tracking_name(points: int) -> str:
    return {1: "one_point", 3: "three_point"}[points]


def example_inputs(max_observers: int, generator: torch.Generator):
    """Seeded inputs with realistic ranges for every model (used for export and parity)."""
    n = max_observers
    ego = torch.randn(1, WINDOW, EGO_DIM, generator=generator) * 0.5
    egonet = torch.randn(1, WINDOW, POSE_DIM, generator=generator)
    gate_features = torch.rand(1, WINDOW, n, K, GATE_FEATURE_DIM, generator=generator)
    exo = torch.randn(1, WINDOW, n, K, EXO_TOKEN_DIM, generator=generator)
    # The last number per keypoint is a gate value in [0, 1], 0 (and the ray zero) for about a
    # fifth of the keypoints, as the engine writes it.
    valid = (torch.rand(1, WINDOW, n, K, 1, generator=generator) > 0.2).float()
    exo = torch.cat([exo[..., :-1], torch.rand(1, WINDOW, n, K, 1, generator=generator)], dim=-1) * valid
    mask = (torch.rand(1, WINDOW, n, generator=generator) > 0.4).float()
    return {"ego": ego, "egonet": egonet, "gate_features": gate_features, "exo": exo, "observer_mask": mask}


def export_one(module: torch.nn.Module, inputs: dict, input_names: list, output_names: list, path: Path) -> dict:
    path.parent.mkdir(parents=True, exist_ok=True)
    module.eval()
    args = tuple(inputs[name] for name in input_names)
    with torch.no_grad(), warnings.catch_warnings():
        # Shape tests in the graphs (`Attention` with one token) are constants at T = 96.
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        torch.onnx.export(module, args, str(path), opset_version=OPSET, dynamo=False,
                          input_names=input_names, output_names=output_names, do_constant_folding=True)
        outputs = module(*args)
    if isinstance(outputs, torch.Tensor):
        outputs = (outputs,)
    data = path.read_bytes()
    return {
        "sha256": hashlib.sha256(data).hexdigest(),
        "bytes": len(data),
        "inputs": [{"name": n, "shape": list(inputs[n].shape)} for n in input_names],
        "outputs": [{"name": n, "shape": list(o.shape)} for n, o in zip(output_names, outputs)],
        "_reference": {"inputs": {n: inputs[n].numpy() for n in input_names},
                       "outputs": {n: o.numpy() for n, o in zip(output_names, outputs)}},
    }


def fusion_networks(fusion: Fusion) -> list:
    """The fusion network's graphs as (manifest name, module, input names, output names): the
    fusion itself and its every-observer-masked form (`FusionEgoOnly`, same weights)."""
    return [
        ("fusion", fusion, ["ego", "egonet", "exo", "observer_mask"], ["root_6d", "body_6d"]),
        ("fusion_ego_only", FusionEgoOnly(fusion), ["ego", "egonet"], ["root_6d", "body_6d"]),
    ]


def export_model_set(egonet: EgoNet, gate: Gate, fusion: Fusion, points: int, max_observers: int, hidden: int,
                     out_dir: Path, prefix: str, seed: int = 0):
    """Exports one tracking mode's networks into ``out_dir/prefix``; returns (manifest entry,
    reference inputs/outputs per model)."""
    generator = torch.Generator().manual_seed(seed)
    inputs = example_inputs(max_observers, generator)
    entries, references = {}, {}
    for name, module, ins, outs in [
        ("egonet", egonet, ["ego"], ["root_6d", "body_6d"]),
        ("gate", gate, ["gate_features"], ["gate"]),
    ] + fusion_networks(fusion):
        rel = f"{prefix}/{name}.onnx"
        entry = export_one(module, inputs, ins, outs, out_dir / rel)
        references[name] = entry.pop("_reference")
        entries[name] = {"file": rel, **entry}
    tracking = tracking_name(points)
    manifest_set = {
        "tracking": tracking,
        "ego_feature_layout": {"version": EGO_LAYOUT_VERSION, "dim": EGO_DIM, "tracking": tracking,
                               "wrists_present": points == 3},
        "gate_feature_layout": {"version": GATE_LAYOUT_VERSION, "dim": GATE_FEATURE_DIM, "context_dim": 0},
        "exo_token_layout": {"version": EXO_TOKEN_LAYOUT_VERSION, "dim": EXO_TOKEN_DIM},
        "max_observers": max_observers,
        "hidden_dim": hidden,
        **entries,
    }
    return manifest_set, references


def write_reference(out_dir: Path, manifest_set: dict, references: dict):
    """Stores one model set's example inputs with the PyTorch and onnxruntime outputs as raw
    little-endian f32 (``reference.bin``) indexed by ``reference.json``: the parity fixture
    that tract (Rust tests) and onnxruntime (Python tests) are checked against."""
    import onnxruntime

    index, blobs, offset = {}, [], 0

    def add(key, array):
        nonlocal offset
        data = np.ascontiguousarray(array, dtype="<f4")
        index[key] = {"offset": offset, "shape": list(data.shape)}
        blobs.append(data.tobytes())
        offset += data.size

    for name, ref in references.items():
        for n, a in ref["inputs"].items():
            add(f"{name}/input/{n}", a)
        for n, a in ref["outputs"].items():
            add(f"{name}/torch/{n}", a)
        session = onnxruntime.InferenceSession(str(out_dir / manifest_set[name]["file"]))
        ort_out = session.run(None, {n: a for n, a in ref["inputs"].items()})
        for meta, a in zip(session.get_outputs(), ort_out):
            add(f"{name}/onnxruntime/{meta.name}", a)
    (out_dir / "reference.bin").write_bytes(b"".join(blobs))
    (out_dir / "reference.json").write_text(json.dumps({"tracking": manifest_set["tracking"], "arrays": index}, indent=1) + "\n")


def write_manifest(out_dir: Path, model_sets: list, training: dict):
    manifest = {"format_version": 1, "window": WINDOW, "fps": 30.0, "model_sets": model_sets, "training": training}
    path = out_dir / "manifest.json"
    if path.exists():
        # The detector (export_movenet.py) is not trained here: its entry stays.
        detector = json.loads(path.read_text()).get("detector")
        if detector is not None:
            manifest["detector"] = detector
    path.write_text(json.dumps(manifest, indent=2) + "\n")


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--random-init", action="store_true", help="export untrained networks (test fixture)")
    parser.add_argument("--hidden", type=int, default=32)
    parser.add_argument("--max-observers", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--output-smoothing", type=float, default=1.0, metavar="SIGMA",
                        help="the fusion network's output low-pass (frames), kept in the fixture so the "
                             "parity tests cover it")
    parser.add_argument("--exo-smoothing", type=float, default=2.0, metavar="SIGMA",
                        help="the fusion network's gate-weighted low-pass of the rays (frames), kept in the "
                             "fixture so the parity tests cover it")
    parser.add_argument("--exo-fade", action=argparse.BooleanOptionalAction, default=True,
                        help="the fusion network fades rays and observers in and out (`faded_exo_tracks`), "
                             "kept in the fixture so the parity tests cover it")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if not args.random_init:
        parser.error("use train.py to export trained networks; this entry point writes fixtures")
    torch.manual_seed(args.seed)
    sets, refs = [], {}
    for points in (1, 3):
        egonet = EgoNet(WINDOW, args.hidden)
        gate = Gate(GATE_FEATURE_DIM, args.hidden)
        fusion = Fusion(WINDOW, args.hidden, heads=4, spatial_layers=1, temporal_layers=1, dropout=0.0,
                        output_smoothing=args.output_smoothing, exo_smoothing=args.exo_smoothing,
                        exo_fade=args.exo_fade)
        entry, ref = export_model_set(egonet, gate, fusion, points, args.max_observers, args.hidden, args.out,
                                      f"{points}pt", seed=args.seed + points)
        sets.append(entry)
        refs[tracking_name(points)] = ref
    write_manifest(args.out, sets, {"data": "none: random initialisation (test fixture)", "seed": args.seed})
    write_reference(args.out, sets[1], refs[tracking_name(3)])
    print(f"wrote {args.out}/manifest.json and reference.json; sizes:",
          {s["tracking"]: sum(s[m]["bytes"] for m in ("egonet", "gate", "fusion")) for s in sets})


if __name__ == "__main__":
    main()
