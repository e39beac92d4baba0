"""The page's lookahead figures from `egoexo eval --live --json`: the networks the worker uses
at each lookahead, and the default decided on unrounded ratios."""

import json
import os
import subprocess
import sys
from pathlib import Path


def row(method, lookahead, mpjpe, ratio, trained=False):
    return {"method": method, "lookahead": lookahead, "trained_for_lookahead": trained, "mpjpe_cm": mpjpe,
            "upper_cm": 0.0, "lower_cm": 2 * mpjpe, "mpjve_cm_s": 0.0, "jitter": 5.0, "frames": 100,
            "vs_offline_cm": 1.0, "mpjpe_ratio": ratio}


def report(tracking, rows):
    offline = [{"method": m, "mpjpe_cm": 10.0, "upper_cm": 0.0, "lower_cm": 20.0, "mpjve_cm_s": 0.0, "jitter": 4.0,
                "frames": 100} for m in ("ego-only", "ego-exo")]
    return {"tracking": tracking, "observers": 1, "subjects": [5, 16], "clips": 2, "frames": 100,
            "offline": offline, "rows": rows}


def figures(tmp_path, reports):
    paths = []
    for i, r in enumerate(reports):
        path = tmp_path / f"r{i}.json"
        path.write_text(json.dumps(r))
        paths.append(str(path))
    out = subprocess.run([sys.executable, "-m", "egoexo_train.live_figures", *paths, "--source", "test"],
                         capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}).stdout
    return json.loads(out)


def test_the_default_is_decided_on_unrounded_ratios_with_the_networks_used(tmp_path):
    three = report(3, [row("ego-exo", 0, 11.03, 1.103), row("ego-exo", 4, 10.2, 1.02),
                       row("ego-only", 0, 11.0, 1.1), row("ego-only", 4, 10.2, 1.02)])
    one = report(1, [row("ego-exo", 0, 10.5, 1.05), row("ego-exo", 4, 10.2, 1.02),
                     row("ego-only", 0, 10.5, 1.05), row("ego-only", 4, 10.2, 1.02)])
    out = figures(tmp_path, [three, one])
    # 1.103 rounds to 1.1 but is not within 10 %: the default is 4.
    assert out["tracking"]["3-point"]["ego-exo"]["0"]["ratio"] == 1.1
    assert out["default"] == 4
    assert out["tracking"]["3-point"]["ego-exo"]["0"]["networks"] == "offline"

    # A live variant for 0 within 10 % replaces the offline networks' figures and makes 0 the default.
    three["rows"].append(row("ego-exo", 0, 10.8, 1.08, trained=True))
    out = figures(tmp_path, [three, one])
    entry = out["tracking"]["3-point"]["ego-exo"]["0"]
    assert entry["networks"] == "live" and entry["mpjpe_cm"] == 10.8
    assert entry["offline_networks"]["mpjpe_cm"] == 11.03
    assert out["default"] == 0
