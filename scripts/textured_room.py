#!/usr/bin/env python3
"""Writes a small textured test scene (public domain, made here): a closed 2 x 2 x 2 room
with a checkerboard floor (map_Kd, repeated twice each way), a red/white striped back
wall, grey walls and ceiling, and a ceiling lamp (Ke), as OBJ + MTL + two PNGs, plus a
TOML scene with a camera inside the room.

    python3 scripts/textured_room.py OUT_DIR
    radiosity bake OUT_DIR/room.toml --lightmap --lightmap-mode moz -o room.glb

Used by checks/gltf/run.sh (three.js must show the texture times the MOZ_lightmap as our
own final-gather render shows it)."""
import os
import struct
import sys
import zlib


def png(path, w, h, px):
    rows = b"".join(b"\0" + bytes(c for x in range(w) for c in px(x, y)) for y in range(h))
    chunk = lambda t, d: struct.pack(">I", len(d)) + t + d + struct.pack(">I", zlib.crc32(t + d) & 0xFFFFFFFF)
    data = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
    data += chunk(b"sRGB", b"\0") + chunk(b"IDAT", zlib.compress(rows, 9)) + chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(data)


def main():
    out = sys.argv[1] if len(sys.argv) > 1 else "textured-room"
    os.makedirs(out, exist_ok=True)
    png(os.path.join(out, "checker.png"), 64, 64,
        lambda x, y: (225, 225, 215) if (x // 8 + y // 8) % 2 == 0 else (40, 60, 150))
    png(os.path.join(out, "stripes.png"), 64, 64,
        lambda x, y: (200, 30, 25) if (x // 8) % 2 == 0 else (230, 230, 230))
    with open(os.path.join(out, "room.mtl"), "w") as f:
        f.write("newmtl checker\nKd 1 1 1\nmap_Kd checker.png\n"
                "newmtl stripes\nKd 1 1 1\nmap_Kd stripes.png\n"
                "newmtl grey\nKd 0.6 0.6 0.6\n"
                "newmtl lamp\nKd 0 0 0\nKe 12 12 11\n")
    # Faces wound counter-clockwise seen from inside the room (their fronts face in).
    quads = [
        ("floor", "checker", [(0, 0, 0), (0, 0, 2), (2, 0, 2), (2, 0, 0)], [(0, 2), (0, 0), (2, 0), (2, 2)]),
        ("back", "stripes", [(0, 0, 0), (2, 0, 0), (2, 2, 0), (0, 2, 0)], [(0, 0), (1, 0), (1, 1), (0, 1)]),
        ("ceiling", "grey", [(0, 2, 0), (2, 2, 0), (2, 2, 2), (0, 2, 2)], None),
        ("left", "grey", [(0, 0, 0), (0, 2, 0), (0, 2, 2), (0, 0, 2)], None),
        ("right", "grey", [(2, 0, 0), (2, 0, 2), (2, 2, 2), (2, 2, 0)], None),
        ("front", "grey", [(0, 0, 2), (0, 2, 2), (2, 2, 2), (2, 0, 2)], None),
        ("lamp", "lamp", [(0.7, 1.99, 0.7), (1.3, 1.99, 0.7), (1.3, 1.99, 1.3), (0.7, 1.99, 1.3)], None),
    ]
    lines = ["# textured room, written by scripts/textured_room.py", "mtllib room.mtl"]
    nv = nt = 0
    for name, mat, vs, uvs in quads:
        lines.append(f"o {name}")
        lines.append(f"usemtl {mat}")
        lines += [f"v {x} {y} {z}" for x, y, z in vs]
        if uvs:
            lines += [f"vt {u} {v}" for u, v in uvs]
            lines.append("f " + " ".join(f"{nv + k + 1}/{nt + k + 1}" for k in range(4)))
            nt += 4
        else:
            lines.append("f " + " ".join(str(nv + k + 1) for k in range(4)))
        nv += 4
    with open(os.path.join(out, "room.obj"), "w") as f:
        f.write("\n".join(lines) + "\n")
    with open(os.path.join(out, "room.toml"), "w") as f:
        f.write('mesh = "room.obj"\n\n[camera]\nposition = [1.0, 1.1, 1.9]\nlook_at = [1.0, 0.6, 0.0]\n'
                'up = [0.0, 1.0, 0.0]\nvfov_deg = 70\n')


if __name__ == "__main__":
    main()
