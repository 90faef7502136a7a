# Imports a GLB in Blender (headless) and checks what a baked file must bring: every mesh
# object with a colour attribute from COLOR_0 (and, when asked, a second UV map from
# TEXCOORD_1), and the camera. Prints one line; exits 1 on a failure.
#   blender -b --factory-startup --python blender_import.py -- FILE.glb MESHES [UV_SETS]
import sys

import numpy

import bpy

# Debian 12's Blender 3.4 glTF importer still uses `np.bool`, which Debian 12's numpy 1.24
# removed; the alias it meant is restored for the import.
if not hasattr(numpy, "bool"):
    numpy.bool = bool

args = sys.argv[sys.argv.index("--") + 1:]
path, want_meshes = args[0], int(args[1])
want_uvs = int(args[2]) if len(args) > 2 else 0
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
cameras = [o for o in bpy.context.scene.objects if o.type == "CAMERA"]
problems = []
if len(meshes) != want_meshes:
    problems.append(f"{len(meshes)} mesh objects, expected {want_meshes}")
for o in meshes:
    attrs = getattr(o.data, "color_attributes", None) or getattr(o.data, "vertex_colors", [])
    if len(attrs) == 0:
        problems.append(f"{o.name}: no colour attribute")
    if len(o.data.uv_layers) < want_uvs:
        problems.append(f"{o.name}: {len(o.data.uv_layers)} UV maps, expected {want_uvs}")
if not cameras:
    problems.append("no camera")
verts = sum(len(o.data.vertices) for o in meshes)
uvs = min((len(o.data.uv_layers) for o in meshes), default=0)
print(f"blender {bpy.app.version_string}: {len(meshes)} meshes, {verts} vertices, {len(cameras)} camera(s), "
      f"at least {uvs} UV map(s) on each, "
      f"colour attributes on {sum(1 for o in meshes if len(getattr(o.data, 'color_attributes', None) or o.data.vertex_colors))}: "
      + ("ok" if not problems else "; ".join(problems[:10])))
sys.stdout.flush()
sys.exit(1 if problems else 0)
