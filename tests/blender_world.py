"""Run docs/exr.md's Blender snippet in Blender's Python module (bpy) and render the world it makes.

Used by tests/test_exr.py (run by a Python with bpy, e.g. ``pip install bpy`` on Python 3.11):

    python tests/blender_world.py DOC EXR OUTDIR  E,N,U [E,N,U ...]

The snippet is taken from the doc as written (its image path replaced by EXR), so the test checks the
code a user copies. For each view direction (Blender x, y, z), a Cycles camera with a 1 deg field of
view renders a 4 x 4 float EXR ``OUTDIR/view_K.exr`` of the world (no denoiser, a box filter of
0.01 pixel, so each pixel is the world's radiance along its ray). Prints one JSON line: the direction
the snippet's sun lamp shines along (its -Z axis).
"""

import json
import math
import pathlib
import re
import sys

import bpy
from mathutils import Vector

document, exr, outdir = (pathlib.Path(argument) for argument in sys.argv[1:4])
views = [Vector([float(c) for c in argument.split(",")]).normalized() for argument in sys.argv[4:]]
snippet = re.search(r"## Blender.*?```python\n(.*?)```", document.read_text(encoding="utf-8"), re.S).group(1)
placeholder = '"/path/to/panorama_frames/frame_00060.exr"'
if placeholder not in snippet:
    sys.exit(f"the Blender snippet no longer loads {placeholder}")
bpy.ops.wm.read_factory_settings(use_empty=True)
exec(compile(snippet.replace(placeholder, repr(str(exr.resolve()))), str(document), "exec"))

scene = bpy.context.scene
bpy.context.view_layer.update()
lamp = bpy.data.objects["clsky sun"]
shines = lamp.matrix_world.to_3x3() @ Vector((0.0, 0.0, -1.0))
lamp.data.energy = 0.0                       # the world alone in the renders
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 4
scene.cycles.use_denoising = False
scene.render.resolution_x = scene.render.resolution_y = 4
scene.render.filter_size = 0.01
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.image_settings.color_depth = "32"
camera = bpy.data.objects.new("probe", bpy.data.cameras.new("probe"))
scene.collection.objects.link(camera)
scene.camera = camera
camera.data.angle = math.radians(1.0)
camera.rotation_mode = "QUATERNION"
for index, view in enumerate(views):
    camera.rotation_quaternion = view.to_track_quat("-Z", "Y")
    scene.render.filepath = str((outdir / f"view_{index}.exr").resolve())
    bpy.ops.render.render(write_still=True)
print(json.dumps({"lamp_shines_along": list(shines)}))
