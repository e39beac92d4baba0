"""Shard loading refuses data from another shard format, naming the file."""

import json

import pytest

from egoexo_train.train import FUSION_KEYS, SHARD_FORMAT_VERSION, load_shards


def test_shards_of_another_format_are_refused(tmp_path):
    (tmp_path / "index.json").write_text(json.dumps({"format_version": SHARD_FORMAT_VERSION - 1, "shards": []}))
    with pytest.raises(SystemExit) as refused:
        load_shards(tmp_path, FUSION_KEYS)
    message = str(refused.value)
    assert str(tmp_path / "index.json") in message and f"expected {SHARD_FORMAT_VERSION}" in message
