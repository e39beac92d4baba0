"""The fusion's cheaper graphs compute the same numbers as the full one: the last spatial
layer's ego-token-only path (`first_query_only`), the every-observer-masked graph
(`Fusion.ego_only`), and the re-export of shipped weights (`egoexo_train.reexport`)."""

import json
from pathlib import Path

import numpy as np
import onnxruntime
import pytest
import torch

from egoexo_train.export import example_inputs
from egoexo_train.model import EGO_DIM, EncoderLayer, Fusion, FusionEgoOnly
from egoexo_train.reexport import fusion_from_onnx, module_name

FIXTURE = Path(__file__).resolve().parents[2] / "crates" / "egoexo-infer" / "tests" / "fixtures" / "models"


def test_first_query_only_is_the_first_token_of_the_full_layer():
    torch.manual_seed(3)
    layer = EncoderLayer(32, 4, 64, dropout=0.0).eval()
    x = torch.randn(96, 4, 32)
    key_bias = torch.tensor([0.0, 0.0, -1.0e4, 0.0]).expand(96, 4).clone()
    with torch.no_grad():
        full = layer(x, key_bias)[:, :1]
        first = layer(x, key_bias, first_query_only=True)
    assert first.shape == (96, 1, 32)
    assert torch.allclose(full, first, atol=1e-6), float((full - first).abs().max())


@pytest.mark.parametrize("spatial_layers,fade", [(1, True), (2, False)])
def test_ego_only_equals_the_fusion_with_every_observer_masked(spatial_layers, fade):
    torch.manual_seed(4)
    fusion = Fusion(96, 32, 4, spatial_layers, 1, dropout=0.0, output_smoothing=1.0,
                    exo_smoothing=2.0 if fade else 0.0, exo_fade=fade).eval()
    inputs = example_inputs(3, torch.Generator().manual_seed(5))
    ego, egonet = inputs["ego"], inputs["egonet"]
    with torch.no_grad():
        # Whatever the rays say, masked observers are not attended to.
        masked = fusion(ego, egonet, inputs["exo"] * 3.0, torch.zeros(1, 96, 3))
        alone = FusionEgoOnly(fusion)(ego, egonet)
        with_observers = fusion(ego, egonet, inputs["exo"], torch.ones(1, 96, 3))
    for a, b in zip(masked, alone):
        assert torch.allclose(a, b, atol=1e-6), float((a - b).abs().max())
    # ...and the observers do change the output when present (the test can fail).
    assert float((with_observers[1] - alone[1]).abs().max()) > 1e-3


def test_module_names_follow_the_exporters_node_paths():
    assert module_name("/spatial.0/attn/qkv/MatMul") == "spatial.0.attn.qkv"
    assert module_name("/spatial.0/ff/ff.0/MatMul") == "spatial.0.ff.0"
    assert module_name("/root_head/root_head.2/MatMul") == "root_head.2"
    assert module_name("/ego_token/MatMul") == "ego_token"


def test_weights_read_back_from_onnx_reproduce_the_file():
    # The engine fixture's fusion (export.py --random-init: hidden 32, 4 heads, 1 spatial and
    # 1 temporal layer, output smoothing 1, exo smoothing 2 with fade).
    manifest = json.loads((FIXTURE / "manifest.json").read_text())
    model_set = next(s for s in manifest["model_sets"] if s["tracking"] == "three_point")
    settings = {"hidden": model_set["hidden_dim"], "heads": 4, "spatial_layers": 1, "temporal_layers": 1,
                "output_smoothing": 1.0, "exo_smoothing": 2.0, "exo_fade": True}
    path = FIXTURE / model_set["fusion"]["file"]
    fusion = fusion_from_onnx(path, settings, manifest["window"])
    inputs = example_inputs(model_set["max_observers"], torch.Generator().manual_seed(9))
    names = ["ego", "egonet", "exo", "observer_mask"]
    session = onnxruntime.InferenceSession(str(path))
    expected = session.run(None, {n: inputs[n].numpy() for n in names})
    with torch.no_grad():
        got = fusion(*(inputs[n] for n in names))
    for g, e in zip(got, expected):
        assert np.abs(g.numpy() - e).max() <= 1e-5
    assert inputs["ego"].shape[-1] == EGO_DIM
