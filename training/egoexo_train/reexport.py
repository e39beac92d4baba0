"""Re-exports shipped fusion networks from their own ONNX weights with the current graph.

The fusion's weights are read back out of each shipped ``fusion.onnx`` (named initializers, and
the constant-folded ``onnx::MatMul_*`` products mapped to their layers through the node that
consumes them), loaded into `Fusion` with the manifest's recorded settings, and exported again
with `export.fusion_networks`: today's graph (the last spatial layer computes the ego token
alone) and the every-observer-masked graph (``fusion_ego_only.onnx``). Nothing is retrained.

Every step is checked against the file it replaces, in onnxruntime, on seeded inputs (random
observers and every observer masked): the rebuilt PyTorch module, the new fusion graph and the
ego-only graph must each agree with the old graph within `TOLERANCE`; otherwise nothing is
written. The manifest's entries (file, sha256, bytes, shapes) are updated in place.

    python -m egoexo_train.reexport --models models
"""

import argparse
import json
from pathlib import Path

import numpy as np
import onnx
import onnxruntime
import torch
from onnx import numpy_helper

from .export import example_inputs, export_one, fusion_networks
from .model import Fusion

#: Largest |difference| allowed between the old and the re-exported graphs' outputs.
TOLERANCE = 1e-4


def module_name(node_name: str) -> str:
    """``/spatial.0/ff/ff.0/MatMul`` -> ``spatial.0.ff.0``: a node's module path as PyTorch
    names it (the exporter repeats the parent's name in a child's: ``ff`` / ``ff.0``)."""
    parts = node_name.strip("/").split("/")[:-1]
    name = []
    for part in parts:
        if name and part.startswith(name[-1] + "."):
            name[-1] = part
        else:
            name.append(part)
    return ".".join(name)


def fusion_state_from_onnx(path: Path) -> dict:
    """The fusion's ``state_dict`` read out of an exported graph: named initializers as they
    are, each ``onnx::MatMul_*`` as the transposed weight of the layer whose MatMul consumes it,
    the two token-type rows (constant-folded adds after the ego and exo embeddings), and, in a
    layer exported with `first_query_only`, the query and key/value slices of ``attn.qkv``
    (products and adds of the attention module itself) joined back into one weight and bias."""
    graph = onnx.load(str(path)).graph
    produced_by = {out: node for node in graph.node for out in node.output}
    state = {}
    token_type = {}
    # attention module -> {"weight"|"bias": [slices]}, joined below (query rows, then key/value).
    qkv_slices = {}
    values = {init.name: torch.from_numpy(numpy_helper.to_array(init).copy()) for init in graph.initializer}
    # The exporter keeps one copy of equal constants and hands it on under the other names
    # through Identity nodes.
    for node in graph.node:
        if node.op_type == "Identity" and node.input[0] in values:
            values[node.output[0]] = values[node.input[0]]
    for name, value in values.items():
        if not name.startswith("onnx::"):
            state[name] = value
    uses = [(node, values[i]) for node in graph.node if node.op_type != "Identity"
            for i in node.input if i in values and i.startswith("onnx::")]
    for node, value in uses:
        module = module_name(node.name)
        if node.op_type == "MatMul" and module.endswith(".attn"):
            qkv_slices.setdefault(module, {}).setdefault("weight", []).append(value.T)
        elif node.op_type == "MatMul":
            state[module + ".weight"] = value.T.contiguous()
        elif node.op_type == "Add" and module.endswith(".attn"):
            qkv_slices.setdefault(module, {}).setdefault("bias", []).append(value)
        elif node.op_type == "Add":
            source = next((produced_by[i] for i in node.input if i in produced_by
                           and produced_by[i].op_type != "Identity"), None)
            if source is not None and source.name == "/ego_token/Add":
                token_type[0] = value
            elif source is not None and source.name == "/exo_token/Add":
                token_type[1] = value
            else:
                raise ValueError(f"{path}: cannot place a constant added by {node.name}")
        else:
            raise ValueError(f"{path}: cannot place a constant used by {node.op_type} {node.name}")
    if sorted(token_type) != [0, 1]:
        raise ValueError(f"{path}: token-type rows not found (found {sorted(token_type)})")
    state["token_type"] = torch.stack([token_type[0], token_type[1]])
    for module, parts in qkv_slices.items():
        for kind in ("weight", "bias"):
            pieces = sorted(parts.get(kind, []), key=lambda t: t.shape[0])
            if len(pieces) != 2 or pieces[1].shape[0] != 2 * pieces[0].shape[0]:
                raise ValueError(f"{path}: {module} has query and key/value {kind} slices of sizes "
                                 f"{[p.shape[0] for p in pieces]}, expected d and 2d")
            state[f"{module}.qkv.{kind}"] = torch.cat(pieces).contiguous()
    return state


def fusion_from_onnx(path: Path, settings: dict, window: int) -> Fusion:
    """A `Fusion` with the settings recorded in the manifest's training section and the
    weights of `path`; every parameter must be found (strict load)."""
    fusion = Fusion(window, settings["hidden"], settings["heads"], settings["spatial_layers"],
                    settings["temporal_layers"], dropout=0.0, exo_embed=settings.get("exo_embed", "linear"),
                    output_smoothing=settings.get("output_smoothing", 0.0),
                    exo_smoothing=settings.get("exo_smoothing", 0.0), exo_fade=settings.get("exo_fade", False))
    fusion.load_state_dict(fusion_state_from_onnx(path), strict=True)
    return fusion.eval()


def check_inputs(max_observers: int) -> list:
    """Seeded fusion inputs: random observers (three seeds) and every observer masked."""
    cases = []
    for seed in (11, 12, 13):
        inputs = example_inputs(max_observers, torch.Generator().manual_seed(seed))
        cases.append({k: inputs[k] for k in ("ego", "egonet", "exo", "observer_mask")})
    masked = dict(cases[0])
    masked["exo"] = torch.zeros_like(masked["exo"])
    masked["observer_mask"] = torch.zeros_like(masked["observer_mask"])
    cases.append(masked)
    return cases


def max_diff(a: list, b: list) -> float:
    return max(float(np.abs(np.asarray(x) - np.asarray(y)).max()) for x, y in zip(a, b))


def run_onnx(path: Path, inputs: dict) -> list:
    session = onnxruntime.InferenceSession(str(path))
    return session.run(None, {i.name: inputs[i.name].numpy() for i in session.get_inputs()})


def reexport_set(models: Path, model_set: dict, settings: dict, window: int, staging: Path) -> dict:
    """Rebuilds one set's fusion, checks it, exports its graphs into `staging`; returns the
    new manifest entries by network name."""
    old = models / model_set["fusion"]["file"]
    fusion = fusion_from_onnx(old, settings, window)
    cases = check_inputs(model_set["max_observers"])
    for case in cases:
        with torch.no_grad():
            rebuilt = [t.numpy() for t in fusion(**case)]
        diff = max_diff(rebuilt, run_onnx(old, case))
        if diff > TOLERANCE:
            raise SystemExit(f"{old}: the rebuilt PyTorch fusion differs from the file by {diff:.2e}")
    entries = {}
    prefix = str(Path(model_set["fusion"]["file"]).parent)
    for name, module, ins, outs in fusion_networks(fusion):
        rel = f"{prefix}/{name}.onnx"
        exported = export_one(module, cases[0], ins, outs, staging / rel)
        exported.pop("_reference", None)
        for case in cases:
            expected = run_onnx(old, case)
            if name == "fusion_ego_only":
                if case["observer_mask"].any():
                    continue
            diff = max_diff(run_onnx(staging / rel, case), expected)
            if diff > TOLERANCE:
                raise SystemExit(f"{rel}: the re-exported graph differs from {old} by {diff:.2e}")
            print(f"  {rel}: max |diff| {diff:.1e} against {old.name} "
                  f"({'every observer masked' if not case['observer_mask'].any() else 'observers'})")
        entries[name] = {"file": rel, **exported}
    return entries


def settings_for(manifest: dict, model_set: dict) -> dict:
    tracking = model_set["tracking"]
    key = tracking if model_set.get("lookahead") is None else f"{tracking}-live{model_set['lookahead']}"
    settings = manifest.get("training", {}).get(key, {}).get("fusion")
    if not isinstance(settings, dict) or "hidden" not in settings:
        raise SystemExit(f"manifest.json: training.{key}.fusion does not record the fusion's settings")
    return settings


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--models", type=Path, required=True, help="the models folder (manifest.json)")
    args = parser.parse_args()
    manifest_path = args.models / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    staging = args.models / ".reexport"
    new_entries = []
    for model_set in manifest["model_sets"]:
        print(f"{model_set['tracking']} (lookahead {model_set.get('lookahead')}):")
        new_entries.append(reexport_set(args.models, model_set, settings_for(manifest, model_set),
                                        manifest["window"], staging))
    # Every set checked: move the files in and update the manifest.
    for model_set, entries in zip(manifest["model_sets"], new_entries):
        for name, entry in entries.items():
            (staging / entry["file"]).replace(args.models / entry["file"])
            model_set[name] = entry
    for leftover in sorted(staging.rglob("*"), reverse=True):
        leftover.rmdir()
    staging.rmdir()
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    print(f"updated {manifest_path}")


if __name__ == "__main__":
    main()
