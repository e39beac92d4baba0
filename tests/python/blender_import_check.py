"""Imports egoexo's BVH and glb exports into Blender (the `bpy` module: a Blender build as a
Python package) with the settings docs/exports.md gives, and compares every joint at every
frame with the CSV export of the same reconstruction.

Not run by CI (bpy is a 350 MB install); run by hand when the exporters or the docs change:

    python3.11 -m venv /tmp/bpy && /tmp/bpy/bin/pip install bpy==4.2.0
    /tmp/bpy/bin/python tests/python/blender_import_check.py S.bvh S.glb S.csv

Prints one JSON line: Blender's version, the scene's frame rate and range after each import,
and the largest joint distance (metres) between Blender's armature and the CSV.
"""

import csv
import json
import sys

import bpy
from mathutils import Vector


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, rows = rows[0], rows[1:]
    names = [h[:-2] for h in header[2::3]]
    frames = [[Vector((float(r[2 + 3 * j]), float(r[3 + 3 * j]), float(r[4 + 3 * j]))) for j in range(len(names))] for r in rows]
    return names, frames


def y_up(v):
    """Blender's Z-up world → egoexo's Y-up world (both importers turn Y up into Z up)."""
    return Vector((v.x, v.z, -v.y))


def armature():
    return next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")


def worst_distance(names, frames, first_frame, bone_name):
    """Largest distance between a bone head (world, Y up) and the CSV's joint, over all frames."""
    arm = armature()
    scene = bpy.context.scene
    worst = 0.0
    for i, joints in enumerate(frames):
        scene.frame_set(first_frame + i)
        for j, name in enumerate(names):
            bone = arm.pose.bones.get(bone_name(name))
            if bone is None:
                continue
            head = y_up(arm.matrix_world @ bone.head)
            worst = max(worst, (head - joints[j]).length)
    return worst


def reset():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def main():
    bvh, glb, csv_path = sys.argv[1:4]
    names, frames = read_csv(csv_path)
    report = {"blender": bpy.app.version_string, "frames": len(frames)}

    reset()
    # The BVH importer's defaults keep the file's 24 fps scene and frames 1-250; these two
    # options take the file's rate (30 fps) and its whole length.
    bpy.ops.import_anim.bvh(filepath=bvh, use_fps_scale=False, update_scene_fps=True, update_scene_duration=True)
    scene = bpy.context.scene
    report["bvh"] = {
        "fps": scene.render.fps / scene.render.fps_base,
        "frame_start": scene.frame_start,
        "frame_end": scene.frame_end,
        "max_joint_error_m": worst_distance(names, frames, scene.frame_start, lambda n: n),
    }

    reset()
    # The glTF importer turns the file's seconds into frames at the scene's rate: set the
    # session's rate first (Output Properties → Frame Rate), else a 30 fps take plays at 24.
    bpy.context.scene.render.fps = round(report["bvh"]["fps"])
    bpy.context.scene.render.fps_base = 1.0
    bpy.ops.import_scene.gltf(filepath=glb)
    scene = bpy.context.scene
    arm = armature()
    action = arm.animation_data.action if arm.animation_data else None
    start = int(action.frame_range[0]) if action else scene.frame_start
    report["glb"] = {
        "fps": scene.render.fps / scene.render.fps_base,
        "action_frames": [int(action.frame_range[0]), int(action.frame_range[1])] if action else None,
        "max_joint_error_m": worst_distance(names, frames, start, lambda n: n),
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()
