#!/usr/bin/env python3
"""Writes the hand-made seed inputs into fuzz/corpus/<target>/ (seed-*), plus copies of
small public-domain / in-repo scene files. Run from anywhere; idempotent."""
import base64, json, os, shutil, struct

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)
SEP = b"\0"

def put(target, name, data):
    d = os.path.join(HERE, "corpus", target)
    os.makedirs(d, exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(os.path.join(d, "seed-" + name), "wb") as f:
        f.write(data)

def read(rel):
    with open(os.path.join(ROOT, rel), "rb") as f:
        return f.read()

# --- OBJ (+ MTL after a NUL) ---
cornell_obj = read("crates/radiosity/data/cornell/cornell_box.obj")
cornell_mtl = read("crates/radiosity/data/cornell/cornell_box.mtl")
put("obj", "cornell", cornell_obj + SEP + cornell_mtl)
put("obj", "triangle", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
put("obj", "quad-mtl", "mtllib m.mtl\no floor\nusemtl white\nv 0 0 0\nv 2 0 0\nv 2 0 2\nv 0 0 2\nf 1/1/1 2/2/1 3/3/1 4/4/1\n"
    "g lamp\nusemtl light\nv 0.5 1 0.5\nv 1.5 1 0.5\nv 1.5 1 1.5\nf -3 -2 -1\n\0"
    "newmtl white\nKd 0.7 0.7 0.7\nnewmtl light\nKd 0\nKe 10 10 10\nmap_Kd tex.png\n")
put("obj", "concave-nonplanar", "v 0 0 0\nv 4 0 0\nv 4 4 0\nv 2 1 0\nv 0 4 0\nf 1 2 3 4 5\n"
    "v 0 0 1\nv 1 0 1\nv 1 1 1.5\nv 0 1 1\nf 6 7 \\\n 8 9\nl 1 2\ns off\n# comment\n")

# --- glTF JSON (+ external buffer after a NUL) and GLB ---
def tri_gltf(uri=None, buf=None, extra=None):
    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    idx = struct.pack("<3H", 0, 1, 2) + b"\0\0"
    data = pos + idx
    g = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "translation": [0, 0, 1], "children": [1]},
                  {"mesh": 0, "matrix": [1, 0, 0, 0, 0, 0, -1, 0, 0, 1, 0, 0, 0, 0, 0, 1]}],
        "meshes": [{"name": "tri", "primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0, "mode": 4}]}],
        "materials": [{"name": "lamp", "doubleSided": True, "emissiveFactor": [1, 0.5, 0.25],
                        "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 4}},
                        "pbrMetallicRoughness": {"baseColorFactor": [0.5, 0.5, 0.5, 1]}}],
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 6}],
        "buffers": [{"byteLength": len(data)}],
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.7, "znear": 0.1, "aspectRatio": 1.0}}],
    }
    if uri == "data":
        g["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode()
    elif uri:
        g["buffers"][0]["uri"] = uri
    if extra:
        extra(g)
    return g, data

g, _ = tri_gltf("data")
put("gltf", "tri-embedded", json.dumps(g, indent=1))
g, data = tri_gltf("tri%20buffer.bin")
put("gltf", "tri-external", json.dumps(g).encode() + SEP + data)

def camera_node(g):
    g["nodes"].append({"camera": 0, "translation": [0.3, 0.3, 3], "rotation": [0, 0, 0, 1]})
    g["scenes"][0]["nodes"].append(2)
    g["meshes"][0]["primitives"][0].pop("indices")
    g["meshes"][0]["primitives"].append({"attributes": {"POSITION": 0}, "mode": 6})
g, _ = tri_gltf("data", extra=camera_node)
put("gltf", "tri-camera-fan", json.dumps(g))

g, data = tri_gltf(None)
js = json.dumps(g).encode()
js += b" " * ((4 - len(js) % 4) % 4)
data += b"\0" * ((4 - len(data) % 4) % 4)
body = struct.pack("<I4s", len(js), b"JSON") + js + struct.pack("<I4s", len(data), b"BIN\0") + data
put("gltf", "tri.glb", b"glTF" + struct.pack("<II", 2, 12 + len(body)) + body)

# --- TOML (+ mesh file after a NUL, written to m.obj and m.gltf) ---
put("toml", "cornell-blue-light", read("scenes/cornell-blue-light.toml"))
put("toml", "builtin-furnace", 'mesh = "builtin:furnace"\ntwo_sided = true\n')
put("toml", "obj-mesh", 'meshes = ["m.obj", "builtin:cornell"]\ncamera = "camera.json"\n'
    '[materials."wall 1"]\nreflectance = [0.5, 0.5, 0.5]\ntwo_sided = true\n\0'
    "mtllib m.mtl\no wall 1\nusemtl wall 1\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
g, _ = tri_gltf("data")
g["materials"][0]["pbrMetallicRoughness"]["baseColorFactor"] = [1, 1, 1, 1]
put("toml", "gltf-mesh", 'mesh = "m.gltf"\n[camera]\nposition = [0, 0, 5]\nlook_at = [0, 0, 0]\nvfov_deg = 40\n'
    '[materials.lamp]\nreflectance = [0.2, 0.2, 0.2]\nemission = [1, 1, 1]\n\0' + json.dumps(g))

# --- View3D .vs3 ---
put("vs3", "ParallelPlanes", read("crates/radiosity/tests/data/ParallelPlanes.vs3"))
put("vs3", "box345", read("crates/radiosity/tests/data/box345.vs3"))
put("vs3", "subsurface-obstruction",
    "T sub and obstruction\nC encl=0 eps=1e-4 list=1\nF 3\n"
    "V 1 0 0 0\nV 2 4 0 0\nV 3 4 4 0\nV 4 0 4 0\nV 5 1 1 0\nV 6 2 1 0\nV 7 2 2 0\nV 8 1 2 0\n"
    "V 9 0 0 2\nV 10 4 0 2\nV 11 0 4 2\n"
    "S 1 1 2 3 4 0 0 0.9 floor\nS 2 5 6 7 8 1 0 0.5 window\nS 3 9 11 10 0 0 0 1.2 roof\n"
    "S 4 9 10 11 0 0 3 0.5 roofback\nO 5 5 6 10 0 blocker\nE\n")

# --- camera / views JSON ---
put("camera", "cornell-camera", read("crates/radiosity/data/cornell/camera.json"))
put("camera", "views-array", '[{"name": "front", "position": [0, 0, -5], "look_at": [0, 0, 0], "vfov_deg": 45},'
    ' {"position": [1, 2, 3], "look_at": [0, 0, 0], "up": [0, 0, 1], "vfov_deg": 30}]')
put("camera", "views-object", '{"views": [{"name": "a.b-c_1", "position": [0, 1e3, 0], "look_at": [0, 0, 0],'
    ' "up": [1, 0, 0], "vfov_deg": 179.5}]}')

# After `cargo fuzz cmin` the seeds reappear under their SHA-1 names: drop those copies.
import hashlib
for t in os.listdir(os.path.join(HERE, "corpus")):
    d = os.path.join(HERE, "corpus", t)
    for f in os.listdir(d):
        if f.startswith("seed-"):
            with open(os.path.join(d, f), "rb") as fh:
                h = hashlib.sha1(fh.read()).hexdigest()
            if os.path.exists(os.path.join(d, h)):
                os.remove(os.path.join(d, h))
