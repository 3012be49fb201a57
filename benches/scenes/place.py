#!/usr/bin/env python3
"""Rewrites a .glb so that the same scene is larger, smaller, elsewhere, or
set in a much larger one: the scenes behind the scale and placement figures
in `integrator::RayOffset`, `Scene::move_to_origin` and the `movies` global
pass's `meshing_size` (all made from `tests/data/scenes/l_hall.glb`).

    python3 benches/scenes/place.py IN.glb OUT.glb scale K
        every length times K: the file's roots hang from one more node
        scaling by K; camera near/far planes times K, point and spot
        intensities times K^2 (so the light arriving is the same)
    python3 benches/scenes/place.py IN.glb OUT.glb move D
        the roots hang from one more node moving them by (D, D/2, -0.7 D)
    python3 benches/scenes/place.py IN.glb OUT.glb ground HALF SHIFT
        the roots hang from one more node moving them by (SHIFT, 0, SHIFT),
        over a square ground 2 HALF across at y = -1 centred on the origin,
        facing up, of the file's first material

Then render OUT.glb and the original with the same settings and compare
(`radcache compare`): a renderer that does not care where a scene is, or
its unit, gives the same frames. The figures cited were made with
`radcache render OUT.glb --method path --spp 64 --size 96x60 --frames 0..4`
against the same of IN.glb. Standard library only.
"""
import json
import struct
import sys

GLB_MAGIC, JSON_CHUNK, BIN_CHUNK = 0x46546C67, 0x4E4F534A, 0x004E4942


def read_glb(path):
    try:
        data = open(path, "rb").read()
    except OSError as e:
        sys.exit(f"{path}: cannot be read: {e.strerror}")
    if data[:4] != b"glTF":
        sys.exit(f"{path}: not a binary glTF (.glb) file")
    try:
        json_len = struct.unpack_from("<I", data, 12)[0]
        document = json.loads(data[20 : 20 + json_len])
    except (struct.error, ValueError) as e:
        sys.exit(f"{path}: not a well-formed .glb file ({e})")
    at = 20 + json_len
    binary = b""
    if at < len(data):
        bin_len = struct.unpack_from("<I", data, at)[0]
        binary = data[at + 8 : at + 8 + bin_len]
    return document, binary


def padded(chunk, fill):
    return chunk + fill * ((4 - len(chunk) % 4) % 4)


def write_glb(path, document, binary):
    if binary:
        document["buffers"] = [{"byteLength": len(binary)}]
    text = padded(json.dumps(document).encode(), b" ")
    body = struct.pack("<II", len(text), JSON_CHUNK) + text
    if binary:
        blob = padded(binary, b"\0")
        body += struct.pack("<II", len(blob), BIN_CHUNK) + blob
    with open(path, "wb") as out:
        out.write(struct.pack("<III", GLB_MAGIC, 2, 12 + len(body)) + body)


def hang_roots(document, node):
    """Puts the scene's root nodes under `node`, a new last root."""
    scene = document["scenes"][document.get("scene", 0)]
    node["children"] = scene["nodes"]
    document["nodes"].append(node)
    scene["nodes"] = [len(document["nodes"]) - 1]
    return scene


def scale(document, k):
    hang_roots(document, {"name": "world_scale", "scale": [k, k, k]})
    for camera in document.get("cameras", []):
        perspective = camera.get("perspective")
        if perspective:
            perspective["znear"] = perspective.get("znear", 0.01) * k
            if "zfar" in perspective:
                perspective["zfar"] *= k
    lights = document.get("extensions", {}).get("KHR_lights_punctual", {})
    for light in lights.get("lights", []):
        if light["type"] != "directional":
            light["intensity"] = light.get("intensity", 1.0) * k * k
            if "range" in light:
                light["range"] *= k


def move(document, d):
    hang_roots(document, {"name": "world_shift", "translation": [d, d * 0.5, -d * 0.7]})


def add_view(document, binary, data, target=None):
    """Appends `data` to the buffer; returns its buffer view's index."""
    binary += b"\0" * ((4 - len(binary) % 4) % 4)
    view = {"buffer": 0, "byteOffset": len(binary), "byteLength": len(data)}
    if target:
        view["target"] = target
    document.setdefault("bufferViews", []).append(view)
    return binary + data, len(document["bufferViews"]) - 1


def ground(document, binary, half, shift):
    scene = hang_roots(document, {"name": "room_shift", "translation": [shift, 0.0, shift]})
    corners = [(-half, -1.0, -half), (half, -1.0, -half), (half, -1.0, half), (-half, -1.0, half)]
    positions = struct.pack("<12f", *[c for corner in corners for c in corner])
    # Counter-clockwise seen from above: the ground faces up (+Y).
    indices = struct.pack("<6I", 0, 2, 1, 0, 3, 2)
    binary, position_view = add_view(document, binary, positions, 34962)
    binary, index_view = add_view(document, binary, indices, 34963)
    accessors = document.setdefault("accessors", [])
    accessors.append(
        {
            "bufferView": position_view,
            "componentType": 5126,
            "count": 4,
            "type": "VEC3",
            "min": [-half, -1.0, -half],
            "max": [half, -1.0, half],
        }
    )
    accessors.append({"bufferView": index_view, "componentType": 5125, "count": 6, "type": "SCALAR"})
    primitive = {"attributes": {"POSITION": len(accessors) - 2}, "indices": len(accessors) - 1}
    if document.get("materials"):
        primitive["material"] = 0
    document.setdefault("meshes", []).append({"name": "ground", "primitives": [primitive]})
    document["nodes"].append({"name": "ground", "mesh": len(document["meshes"]) - 1})
    scene["nodes"].append(len(document["nodes"]) - 1)
    return binary


def main(argv):
    usage = "usage: place.py IN.glb OUT.glb (scale K | move D | ground HALF SHIFT)"
    if len(argv) < 5:
        sys.exit(usage)
    source, target, how, numbers = argv[1], argv[2], argv[3], argv[4:]
    try:
        numbers = [float(n) for n in numbers]
    except ValueError:
        sys.exit(f"{usage}\nnot a number among {argv[4:]}")
    document, binary = read_glb(source)
    if how == "scale" and len(numbers) == 1:
        scale(document, numbers[0])
    elif how == "move" and len(numbers) == 1:
        move(document, numbers[0])
    elif how == "ground" and len(numbers) == 2:
        binary = ground(document, binary, *numbers)
    else:
        sys.exit(usage)
    write_glb(target, document, binary)


if __name__ == "__main__":
    main(sys.argv)
