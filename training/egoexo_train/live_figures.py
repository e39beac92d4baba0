"""The page's lookahead figures (``web/live-lookahead.json``) from ``egoexo eval --live --json``.

For each tracking mode and method, per lookahead L: the figures of the networks the page's
worker reads L out with (the live variant trained for L where the manifest ships one, with
``"networks": "live"``; else the offline networks), and the default the page selects: the
smallest L whose ego-exo MPJPE is within 10 % of the offline result in every tracking mode.

Example:
    egoexo eval ... --tracking 3 --models models --live --json > eval-live3.json
    egoexo eval ... --tracking 1 --models models --live --json > eval-live1.json
    python -m egoexo_train.live_figures eval-live3.json eval-live1.json --source "..." > web/live-lookahead.json
"""

import argparse
import json
from pathlib import Path

#: The page's default is the smallest lookahead within this ratio of the offline MPJPE.
WITHIN_OFFLINE = 1.10


def figures(metrics: dict, ratio: float) -> dict:
    return {"mpjpe_cm": round(metrics["mpjpe_cm"], 2), "lower_cm": round(metrics["lower_cm"], 2),
            "jitter": round(metrics["jitter"], 2), "ratio": round(ratio, 2)}


def tables(report: dict) -> dict:
    """``{method: {"offline": ..., "L": ...}}`` for one tracking mode."""
    out = {}
    for row in report["offline"]:
        out[row["method"]] = {"offline": figures(row, 1.0)}
    for row in sorted(report["rows"], key=lambda r: (r["lookahead"], r.get("trained_for_lookahead", False))):
        table = out[row["method"]]
        entry = figures(row, row["mpjpe_ratio"])
        key = str(row["lookahead"])
        if row.get("trained_for_lookahead"):
            # The live variant replaces the offline networks' figures at this lookahead.
            entry["networks"] = "live"
            entry["offline_networks"] = {k: v for k, v in table[key].items() if k != "networks"}
        else:
            entry["networks"] = "offline"
        table[key] = entry
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("reports", type=Path, nargs="+", help="egoexo eval --live --json outputs, one per tracking mode")
    parser.add_argument("--source", required=True, help="how the reports were made (shown in the file)")
    args = parser.parse_args()
    by_mode = {}
    reports = [json.loads(path.read_text()) for path in args.reports]
    for report in reports:
        by_mode[f"{report['tracking']}-point"] = tables(report)
    lookaheads = sorted({int(k) for modes in by_mode.values() for method in modes.values() for k in method
                         if k != "offline"})
    # Decided on the unrounded ratios (a rounded 1.10 may be 1.103).
    used = {}
    for report in reports:
        for row in report["rows"]:
            if row["method"] == "ego-exo":
                key = (report["tracking"], row["lookahead"])
                if row.get("trained_for_lookahead") or key not in used:
                    used[key] = row["mpjpe_ratio"]
    default = next((l for l in lookaheads
                    if all(used[(r["tracking"], l)] <= WITHIN_OFFLINE for r in reports)), lookaheads[-1])
    print(json.dumps({
        "source": args.source,
        "goal": "the default is the smallest lookahead whose MPJPE is within 10 % of the offline result in every "
                "tracking mode (with the networks the worker uses at that lookahead)",
        "tracking": by_mode,
        "default": default,
    }, indent=1))


if __name__ == "__main__":
    main()
