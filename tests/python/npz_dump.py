"""Load an .npz with numpy (no pickles) and dump every array as JSON.

    python npz_dump.py in.npz out.json

Each key maps to {"dtype": str, "shape": [...], "values": flat list (C order) or a string}.
Used by the egoexo-session exporter tests to check that numpy reads the AMASS-style npz;
the geometry is checked on the Rust side, with the project's own forward kinematics.
"""

import json
import sys

import numpy as np


def main(src: str, dst: str) -> None:
    out = {"numpy_version": np.__version__, "arrays": {}}
    with np.load(src, allow_pickle=False) as npz:
        for key in npz.files:
            a = npz[key]
            if a.dtype.kind == "U":
                values = a.tolist()  # a str for a 0-d array
            else:
                values = a.ravel(order="C").astype(np.float64).tolist()
            out["arrays"][key] = {"dtype": a.dtype.str, "shape": list(a.shape), "values": values}
    with open(dst, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: npz_dump.py in.npz out.json")
    main(sys.argv[1], sys.argv[2])
