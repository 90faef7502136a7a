#!/usr/bin/env python3
"""Writes an urban-canyon model as OBJ: a grid of box buildings on a ground plane, every
surface cut into square facets (the kind of model uDALES hands to View3D for its radiation
view factors; about 22 000 facets with the defaults).

    python3 scripts/urban_canyon.py -o canyon.obj          # 21 568 facets
    python3 scripts/urban_canyon.py --blocks 2 -o small.obj

Each facet is its own object (`o f<k>`), so `radiosity viewfactors --per object` gives one
row per facet. Faces point outward (ground up, roofs up, walls away from their building);
units metres. No ground under the buildings, no facets inside walls.
"""
import argparse

ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
ap.add_argument("-o", "--output", required=True)
ap.add_argument("--blocks", type=int, default=4, help="buildings per side (default 4)")
ap.add_argument("--width", type=int, default=12, help="building footprint side in facets (default 12)")
ap.add_argument("--height", type=int, default=18, help="building height in facets (default 18)")
ap.add_argument("--street", type=int, default=8, help="street width in facets (default 8)")
ap.add_argument("--facet", type=float, default=1.0, help="facet size in metres (default 1)")
a = ap.parse_args()

pitch = a.width + a.street
size = a.blocks * pitch + a.street  # streets on every side
s = a.facet
vertices, faces = {}, []


def vid(p):
    key = tuple(round(c * s, 9) for c in p)
    if key not in vertices:
        vertices[key] = len(vertices) + 1
    return vertices[key]


def quad(p0, du, dv):
    """Facet with corner p0 and edges du, dv (counter-clockwise seen from the front)."""
    p1 = tuple(x + y for x, y in zip(p0, du))
    p2 = tuple(x + y + z for x, y, z in zip(p0, du, dv))
    p3 = tuple(x + z for x, z in zip(p0, dv))
    faces.append([vid(p0), vid(p1), vid(p2), vid(p3)])


def inside(x, y):
    """Is the ground cell (x, y) under a building?"""
    bx, by = (x - a.street) % pitch, (y - a.street) % pitch
    return x >= a.street and y >= a.street and x < size - a.street and y < size - a.street and bx < a.width and by < a.width


for y in range(size):  # ground, facing up (+z)
    for x in range(size):
        if not inside(x, y):
            quad((x, y, 0), (1, 0, 0), (0, 1, 0))
for j in range(a.blocks):
    for i in range(a.blocks):
        x0, y0, w, h = a.street + i * pitch, a.street + j * pitch, a.width, a.height
        for u in range(w):
            for v in range(w):  # roof
                quad((x0 + u, y0 + v, h), (1, 0, 0), (0, 1, 0))
        for u in range(w):
            for z in range(h):
                quad((x0 + u, y0, z), (1, 0, 0), (0, 0, 1))  # south wall, facing -y
                quad((x0 + u + 1, y0 + w, z), (-1, 0, 0), (0, 0, 1))  # north, +y
                quad((x0, y0 + u + 1, z), (0, -1, 0), (0, 0, 1))  # west, -x
                quad((x0 + w, y0 + u, z), (0, 1, 0), (0, 0, 1))  # east, +x

with open(a.output, "w") as f:
    f.write(f"# urban canyon: {a.blocks}x{a.blocks} buildings {a.width}x{a.width}x{a.height}, streets {a.street}, "
            f"facet {a.facet} m; {len(faces)} facets\n")
    for p in sorted(vertices, key=vertices.get):
        f.write("v %g %g %g\n" % p)
    for k, q in enumerate(faces):
        f.write(f"o f{k}\nf {' '.join(map(str, q))}\n")
print(f"{a.output}: {len(faces)} facets, {len(vertices)} vertices, domain {size * s:g} m")
