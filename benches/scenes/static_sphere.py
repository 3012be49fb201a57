#!/usr/bin/env python3
"""A glTF scene with a large mesh, for measuring what a frame costs beside
its triangles: a closed room (2 x 3 x 4 m) lit by a ceiling panel, a
static UV sphere of 4 * N * (N - 1) triangles and a block that slides along
the floor for one second (24 frames at 24 fps).

    python3 benches/scenes/static_sphere.py N OUT.glb [--moving-light | --moving-panel]

N = 700 gives 1,957,226 triangles in all. With --moving-light the sphere is
the only light instead (radius 0.15 m, emitting), and it slides through the
room above the block. With --moving-panel the sphere stays as it is and the
ceiling panel light slides 1.2 m across the ceiling: a large static mesh
under a moving light. Standard library only.
"""
import json
import math
import struct
import sys


def sphere(n, radius, centre):
    """UV sphere, n rings, 2n segments, seam and poles welded, fronts out."""
    rings = []
    for i in range(n + 1):
        theta = math.pi * i / n
        ring = []
        for j in range(2 * n):
            phi = math.pi * j / n
            if i in (0, n):
                d = (0.0, 1.0 if i == 0 else -1.0, 0.0)
            else:
                d = (math.sin(theta) * math.cos(phi), math.cos(theta), math.sin(theta) * math.sin(phi))
            ring.append(d)
        rings.append(ring)
    normals = [d for ring in rings for d in ring]
    positions = [tuple(centre[k] + radius * d[k] for k in range(3)) for d in normals]
    at = lambda i, j: i * 2 * n + j % (2 * n)
    triangles = []
    for i in range(n):
        for j in range(2 * n):
            a, b, c, d = at(i, j), at(i + 1, j), at(i, j + 1), at(i + 1, j + 1)
            if i != 0:
                triangles.append((a, c, b))
            if i != n - 1:
                triangles.append((c, d, b))
    return positions, normals, triangles


def box(lo, hi, inward):
    positions, normals, triangles = [], [], []
    for axis in range(3):
        for side in (0, 1):
            n = [0.0, 0.0, 0.0]
            n[axis] = (1.0 if side else -1.0) * (-1.0 if inward else 1.0)
            u, v = (axis + 1) % 3, (axis + 2) % 3
            base = len(positions)
            for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                p = [0.0, 0.0, 0.0]
                p[axis] = hi[axis] if side else lo[axis]
                p[u] = hi[u] if du else lo[u]
                p[v] = hi[v] if dv else lo[v]
                positions.append(tuple(p))
                normals.append(tuple(n))
            quad = [(base, base + 1, base + 2), (base, base + 2, base + 3)]
            e1 = [positions[base + 1][k] - positions[base][k] for k in range(3)]
            e2 = [positions[base + 2][k] - positions[base][k] for k in range(3)]
            cross = (e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0])
            if sum(cross[k] * n[k] for k in range(3)) < 0:
                quad = [(a, c, b) for a, b, c in quad]
            triangles += quad
    return positions, normals, triangles


def panel(y, half):
    positions = [(-half, y, -half), (half, y, -half), (half, y, half), (-half, y, half)]
    return positions, [(0.0, -1.0, 0.0)] * 4, [(0, 1, 2), (0, 2, 3)]


def main():
    options = sys.argv[3:]
    if len(sys.argv) < 3 or not sys.argv[1].isdigit() or int(sys.argv[1]) < 2 or len(options) > 1 \
            or any(o not in ("--moving-light", "--moving-panel") for o in options):
        sys.exit(__doc__)
    n, out = int(sys.argv[1]), sys.argv[2]
    moving_light = "--moving-light" in options
    moving_panel = "--moving-panel" in options
    meshes = [
        box((-1.0, 0.0, -2.0), (1.0, 3.0, 2.0), True),
        sphere(n, 0.15, (0.0, 0.0, 0.0)) if moving_light else sphere(n, 0.6, (0.3, 0.6, -0.8)),
        box((-0.2, 0.0, -0.2), (0.2, 0.4, 0.2), False),
        panel(2.99, 0.4),
    ]
    diffuse = lambda rgb: {"pbrMetallicRoughness": {"baseColorFactor": rgb + [1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}}
    light = {**diffuse([0.0, 0.0, 0.0]), "emissiveFactor": [1.0, 1.0, 1.0],
             "extensions": {"KHR_materials_emissive_strength": {"emissiveStrength": 15.0}}}
    materials = [diffuse([0.7, 0.7, 0.7]), light if moving_light else diffuse([0.8, 0.3, 0.2]),
                 diffuse([0.2, 0.5, 0.8]), light]
    buffer, views, accessors, gltf_meshes = bytearray(), [], [], []

    def view(data, target=None):
        while len(buffer) % 4:
            buffer.append(0)
        views.append({"buffer": 0, "byteOffset": len(buffer), "byteLength": len(data), **({"target": target} if target else {})})
        buffer.extend(data)
        return len(views) - 1

    def floats(rows):
        return struct.pack(f"<{len(rows) * len(rows[0])}f", *[x for r in rows for x in r])

    for k, (p, nrm, tris) in enumerate(meshes):
        lo = [min(q[a] for q in p) for a in range(3)]
        hi = [max(q[a] for q in p) for a in range(3)]
        accessors.append({"bufferView": view(floats(p), 34962), "componentType": 5126, "count": len(p), "type": "VEC3", "min": lo, "max": hi})
        accessors.append({"bufferView": view(floats(nrm), 34962), "componentType": 5126, "count": len(nrm), "type": "VEC3"})
        flat = [i for t in tris for i in t]
        accessors.append({"bufferView": view(struct.pack(f"<{len(flat)}I", *flat), 34963), "componentType": 5125, "count": len(flat), "type": "SCALAR"})
        gltf_meshes.append({"primitives": [{"attributes": {"POSITION": len(accessors) - 3, "NORMAL": len(accessors) - 2},
                                            "indices": len(accessors) - 1, "material": k}]})
    times = [i / 24 for i in range(25)]
    moves = [(-0.6 + 0.05 * i, 0.0, 0.8) for i in range(25)]
    accessors.append({"bufferView": view(struct.pack("<25f", *times)), "componentType": 5126, "count": 25, "type": "SCALAR", "min": [0.0], "max": [1.0]})
    accessors.append({"bufferView": view(floats(moves)), "componentType": 5126, "count": 25, "type": "VEC3"})
    flight = [(x, 1.2, z) for x, _, z in moves]
    accessors.append({"bufferView": view(floats(flight)), "componentType": 5126, "count": 25, "type": "VEC3"})
    samplers = [{"input": len(accessors) - 3, "output": len(accessors) - k, "interpolation": "LINEAR"} for k in (2, 1)]
    channels = [{"sampler": 0, "target": {"node": 2, "path": "translation"}}]
    if moving_light:
        channels.append({"sampler": 1, "target": {"node": 1, "path": "translation"}})
    if moving_panel:
        slide = [(-0.6 + 0.05 * i, 0.0, 0.0) for i in range(25)]
        accessors.append({"bufferView": view(floats(slide)), "componentType": 5126, "count": 25, "type": "VEC3"})
        samplers.append({"input": samplers[0]["input"], "output": len(accessors) - 1, "interpolation": "LINEAR"})
        channels.append({"sampler": 2, "target": {"node": 3, "path": "translation"}})
    doc = {
        "asset": {"version": "2.0"},
        "extensionsUsed": ["KHR_materials_emissive_strength"],
        "scene": 0,
        "scenes": [{"nodes": [0, 1, 2, 4] if moving_light else [0, 1, 2, 3, 4]}],
        "nodes": [{"mesh": 0}, {"mesh": 1}, {"mesh": 2, "translation": list(moves[0])}, {"mesh": 3},
                  {"camera": 0, "translation": [0.0, 1.5, 1.95]}],
        "meshes": gltf_meshes,
        "materials": materials,
        "cameras": [{"type": "perspective", "perspective": {"yfov": 0.9, "znear": 0.01, "zfar": 100.0, "aspectRatio": 1.0}}],
        "animations": [{"samplers": samplers, "channels": channels}],
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": len(buffer)}],
    }
    while len(buffer) % 4:
        buffer.append(0)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    with open(out, "wb") as f:
        f.write(struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(text) + 8 + len(buffer)))
        f.write(struct.pack("<II", len(text), 0x4E4F534A) + text)
        f.write(struct.pack("<II", len(buffer), 0x004E4942) + bytes(buffer))
    print(f"{out}: {sum(len(m[2]) for m in meshes)} triangles")


if __name__ == "__main__":
    main()
