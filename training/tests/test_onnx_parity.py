"""onnxruntime runs the exported networks like PyTorch did: the engine's fixture
(crates/egoexo-infer/tests/fixtures/models, written by `egoexo_train.export --random-init`)
stores seeded inputs with the PyTorch and onnxruntime outputs; tract is checked against the
same numbers in crates/egoexo-infer/tests/infer_tests/parity.rs."""

import json
from pathlib import Path

import numpy as np
import onnxruntime

FIXTURE = Path(__file__).resolve().parents[2] / "crates" / "egoexo-infer" / "tests" / "fixtures" / "models"


def reference():
    index = json.loads((FIXTURE / "reference.json").read_text())
    data = np.fromfile(FIXTURE / "reference.bin", dtype="<f4")

    def array(key):
        entry = index["arrays"][key]
        size = int(np.prod(entry["shape"]))
        return data[entry["offset"]:entry["offset"] + size].reshape(entry["shape"])

    return index, array


def test_onnxruntime_matches_pytorch_within_1e_4():
    index, array = reference()
    manifest = json.loads((FIXTURE / "manifest.json").read_text())
    model_set = next(s for s in manifest["model_sets"] if s["tracking"] == index["tracking"])
    for name in ("egonet", "gate", "fusion", "fusion_ego_only"):
        session = onnxruntime.InferenceSession(str(FIXTURE / model_set[name]["file"]))
        inputs = {i.name: array(f"{name}/input/{i.name}") for i in session.get_inputs()}
        outputs = session.run(None, inputs)
        for meta, got in zip(session.get_outputs(), outputs):
            for framework in ("torch", "onnxruntime"):
                expected = array(f"{name}/{framework}/{meta.name}")
                diff = float(np.abs(got - expected).max())
                assert diff <= 1e-4, f"{name}.{meta.name}: onnxruntime vs stored {framework}: {diff}"


def test_manifest_checksums_match_the_files():
    import hashlib

    manifest = json.loads((FIXTURE / "manifest.json").read_text())
    for model_set in manifest["model_sets"]:
        for name in ("egonet", "gate", "fusion", "fusion_ego_only"):
            entry = model_set[name]
            data = (FIXTURE / entry["file"]).read_bytes()
            assert hashlib.sha256(data).hexdigest() == entry["sha256"]
            assert len(data) == entry["bytes"]
