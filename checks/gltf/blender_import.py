# Imports a GLB in Blender (headless) and checks what a baked file must bring: every mesh
# object with a colour attribute from COLOR_0 (and, when asked, a second UV map from
# TEXCOORD_1), and the camera. With TEXTURED (a MOZ_lightmap bake, which has no vertex
# colours), no colour attribute is asked for, and at least TEXTURED materials must show an
# image texture (the base-colour textures kept). Prints one line; exits 1 on a failure.
#   blender -b --factory-startup --python blender_import.py -- FILE.glb MESHES [UV_SETS [TEXTURED]]
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
want_textured = int(args[3]) if len(args) > 3 else None
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.import_scene.gltf(filepath=path)
meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
cameras = [o for o in bpy.context.scene.objects if o.type == "CAMERA"]
problems = []
if len(meshes) != want_meshes:
    problems.append(f"{len(meshes)} mesh objects, expected {want_meshes}")
for o in meshes:
    attrs = getattr(o.data, "color_attributes", None) or getattr(o.data, "vertex_colors", [])
    if len(attrs) == 0 and want_textured is None:
        problems.append(f"{o.name}: no colour attribute")
    if len(o.data.uv_layers) < want_uvs:
        problems.append(f"{o.name}: {len(o.data.uv_layers)} UV maps, expected {want_uvs}")
if not cameras:
    problems.append("no camera")
textured = sum(1 for m in bpy.data.materials if m.use_nodes and any(n.type == "TEX_IMAGE" and n.image for n in m.node_tree.nodes))
if want_textured is not None and textured < want_textured:
    problems.append(f"{textured} materials with an image texture, expected {want_textured}")
verts = sum(len(o.data.vertices) for o in meshes)
uvs = min((len(o.data.uv_layers) for o in meshes), default=0)
print(f"blender {bpy.app.version_string}: {len(meshes)} meshes, {verts} vertices, {len(cameras)} camera(s), "
      f"at least {uvs} UV map(s) on each, {textured} textured material(s), "
      f"colour attributes on {sum(1 for o in meshes if len(getattr(o.data, 'color_attributes', None) or o.data.vertex_colors))}: "
      + ("ok" if not problems else "; ".join(problems[:10])))
sys.stdout.flush()
sys.exit(1 if problems else 0)
