"""Read a BVH with the independent `bvhio` reader (PyPI) and dump every joint's world
position in every frame, as bvhio's own forward kinematics computes it.

    python bvh_world_positions.py in.bvh out.json

Output: {"frame_time": s, "joints": [names in file order], "positions": [frame][joint][xyz]}
in the file's units. The egoexo-session tests compare these with the project's FK.
"""

import json
import sys

import bvhio


def main(src: str, dst: str) -> None:
    container = bvhio.readAsBvh(src)
    root = bvhio.readAsHierarchy(src)
    layout = root.layout()
    positions = []
    for frame in range(container.FrameCount):
        root.loadPose(frame)
        positions.append([list(map(float, joint.PositionWorld)) for joint, _index, _depth in layout])
    out = {
        "frame_time": container.FrameTime,
        "frame_count": container.FrameCount,
        "joints": [joint.Name for joint, _index, _depth in layout],
        "positions": positions,
    }
    with open(dst, "w") as f:
        json.dump(out, f)


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit("usage: bvh_world_positions.py in.bvh out.json")
    main(sys.argv[1], sys.argv[2])
