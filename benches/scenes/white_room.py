#!/usr/bin/env python3
"""A glTF scene where most light has bounced many times: a closed white
room 2 m across of albedo R (every wall, and a thin shelf), a red block
(R, 0.2, 0.2) sliding 0.5 m over one second, and a small ceiling light in
a corner that the camera does not see. At R = 0.9 a radiosity iteration
that stops once a bounce adds under 0.1 % leaves out about 1 % of the
light (`benches/RESULTS.md`, "The bounces the global pass stops
before").

    python3 benches/scenes/white_room.py R OUT.glb

Needs numpy (the scene writer in tests/data/reference/mitsuba/ is used).
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..', '..', 'tests', 'data', 'reference', 'mitsuba'))
from gen import Scene, box  # noqa: E402
from scenes import oquad, look_at_quat  # noqa: E402
from lit_room import room  # noqa: E402


def white_room(albedo):
    S = Scene()
    white = S.mat('white', (albedo, albedo, albedo))
    red = S.mat('red', (albedo, 0.2, 0.2))
    light = S.mat('light', (0, 0, 0), emissive=(1, 1, 1), strength=30.0)
    room(S, white)
    P, N, I = box((0, 0, 0), (0.25, 0.4, 0.25))
    block = S.node('block', t=(0.3, 0.4, -0.3), mesh=S.mesh('block', [(P, N, I, 'u16', red)]))
    S.anim(block, 'translation', [0, 1], [(0.3, 0.4, -0.3), (-0.2, 0.4, -0.3)])
    P, N, I = box((0, 0, 0), (0.6, 0.02, 0.4))
    S.node('shelf', t=(-0.3, 1.0, -0.6), mesh=S.mesh('shelf', [(P, N, I, 'u16', white)]))
    q = oquad([(0.6, 1.98, 0.6), (0.8, 1.98, 0.6), (0.8, 1.98, 0.8), (0.6, 1.98, 0.8)], (0, -1, 0))
    S.node('light', mesh=S.mesh('light', [(*q, 'u16', light)]))
    eye = (0, 1, 0.95)
    S.node('camera', t=eye, r=look_at_quat(eye, (0, 0.6, 0)), camera=True)
    S.camera = dict(yfov=0.9, aspect=1.0, znear=0.05, zfar=100.0)
    return S


if __name__ == '__main__':
    try:
        albedo = float(sys.argv[1]) if len(sys.argv) == 3 else -1.0
    except ValueError:
        albedo = -1.0
    if not 0.0 <= albedo <= 1.0:
        sys.exit(__doc__)
    white_room(albedo).write_glb(sys.argv[2])
