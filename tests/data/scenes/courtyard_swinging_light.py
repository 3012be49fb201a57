"""Writes courtyard_swinging_light.glb: a courtyard (a ground, a red wall
left, a green wall right, a white wall behind, a white block, no roof)
under a point light 40 m away that swings across the sky from low on the
left to low on the right over 24 frames (a sun made of a point light, as
some exporters write one). It moves every shadow the walls cast, so the
methods' temporal reuse is tested on shadows that no moving object casts.

    python3 tests/data/scenes/courtyard_swinging_light.py
    python3 tests/data/scenes/courtyard_swinging_light.py --ground HALF OUT.glb

The second writes the same courtyard on a ground 2·HALF across (still two
triangles) to OUT.glb: the scene behind the figures on `movies`' large
triangles (`src/method/movies/pieces.rs`).
"""
import json, math, os, struct, sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..', 'reference', 'mitsuba'))
from gen import Scene, box  # noqa: E402
from scenes import look_at_quat, oquad  # noqa: E402


def courtyard(half=4.0):
    S = Scene()
    white = S.mat('white', (0.7, 0.7, 0.7))
    red = S.mat('red', (0.7, 0.15, 0.1))
    green = S.mat('green', (0.15, 0.6, 0.2))
    ground = oquad([(-half, 0, -half), (half, 0, -half), (half, 0, half), (-half, 0, half)], (0, 1, 0))
    S.node('ground', mesh=S.mesh('ground', [(*ground, 'u16', white)]))
    for name, centre, half, m in [
            ('left', (-1.55, 1.0, 0.0), (0.05, 1.0, 1.5), red),
            ('right', (1.55, 1.0, 0.0), (0.05, 1.0, 1.5), green),
            ('back', (0.0, 1.0, -1.55), (1.6, 1.0, 0.05), white),
            ('block', (0.3, 0.4, -0.3), (0.3, 0.4, 0.3), white)]:
        P, N, I = box((0, 0, 0), half)
        S.node(name, t=centre, mesh=S.mesh(name, [(P, N, I, 'u16', m)]))
    eye = (0.0, 1.6, 3.6)
    S.node('camera', t=eye, r=look_at_quat(eye, (0.0, 0.6, 0.0)), camera=True)
    S.camera = dict(yfov=0.8, aspect=1.0, znear=0.05, zfar=200.0)
    distance, frames = 40.0, 24
    angles = [math.radians(160 - 140 * f / (frames - 1)) for f in range(frames)]
    places = [(distance * math.cos(a), distance * math.sin(a), 0.3 * distance) for a in angles]
    # A mesh-less node for the light (a marker box, removed below).
    P, N, I = box((0, 0, 0), (0.01, 0.01, 0.01))
    sun = S.node('sun', t=places[0], mesh=S.mesh('marker', [(P, N, I, 'u16', white)]))
    S.anim(sun, 'translation', [f / 24.0 for f in range(frames)], places)
    return S


def with_point_light(path, node_name, colour, intensity):
    """Rewrites the GLB at `path`: node `node_name` loses its mesh and
    carries a KHR_lights_punctual point light."""
    data = open(path, 'rb').read()
    n = struct.unpack('<I', data[12:16])[0]
    doc, rest = json.loads(data[20:20 + n]), data[20 + n:]
    doc.setdefault('extensionsUsed', []).append('KHR_lights_punctual')
    doc.setdefault('extensions', {})['KHR_lights_punctual'] = {
        'lights': [{'type': 'point', 'color': colour, 'intensity': intensity}]}
    for node in doc['nodes']:
        if node.get('name') == node_name:
            node.setdefault('extensions', {})['KHR_lights_punctual'] = {'light': 0}
            node.pop('mesh', None)
    text = json.dumps(doc).encode()
    text += b' ' * ((4 - len(text) % 4) % 4)
    size = 12 + 8 + len(text) + len(rest)
    out = b'glTF' + struct.pack('<II', 2, size) + struct.pack('<I', len(text)) + b'JSON' + text + rest
    open(path, 'wb').write(out)


if __name__ == '__main__':
    if len(sys.argv) == 4 and sys.argv[1] == '--ground':
        half, path = float(sys.argv[2]), sys.argv[3]
    elif len(sys.argv) == 1:
        half, path = 4.0, os.path.join(HERE, 'courtyard_swinging_light.glb')
    else:
        sys.exit(__doc__)
    courtyard(half).write_glb(path)
    with_point_light(path, 'sun', [1.0, 0.95, 0.85], 3000.0)
    print(path)
