#!/usr/bin/env python3
"""A glTF scene of many moving objects under a moving light: a closed room
2 m across, N × N small cubes (6 cm) on a grid, each rising 0.3 m and
turning about its vertical axis, one node each, and a ceiling panel light
sliding 0.8 m, all over one second (24 frames at 24 fps). `trc` traces
its estimate's shadow rays through the cubes as N² instances
(`accel::Instances`; `benches/RESULTS.md`, "The moving objects traced as
instances").

    python3 benches/scenes/many_cubes.py N OUT.glb

N = 20 gives 400 cubes. Needs numpy (the scene writer in
tests/data/reference/mitsuba/ is used).
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..', '..', 'tests', 'data', 'reference', 'mitsuba'))
from gen import Scene, box, axis_angle  # noqa: E402
from lit_room import room, light_and_camera  # noqa: E402


def many_cubes(n):
    S = Scene()
    white = S.mat('white', (0.7, 0.7, 0.7))
    red = S.mat('red', (0.7, 0.1, 0.1))
    light = S.mat('light', (0, 0, 0), emissive=(1, 1, 1), strength=20.0)
    room(S, white)
    P, N, I = box((0, 0, 0), (0.03, 0.03, 0.03))
    cube = S.mesh('cube', [(P, N, I, 'u16', red)])
    step = 1.8 / n
    for i in range(n):
        for j in range(n):
            x, z = -0.9 + i * step, -0.9 + j * step
            y = 0.2 + 0.6 * ((i * 7 + j * 3) % 10) / 10
            c = S.node('cube%d_%d' % (i, j), t=(x, y, z), mesh=cube)
            S.anim(c, 'translation', [0, 1], [(x, y, z), (x, y + 0.3, z)])
            S.anim(c, 'rotation', [0, 1], [axis_angle((0, 1, 0), 0), axis_angle((0, 1, 0), 2.0)])
    light_and_camera(S, light)
    return S


if __name__ == '__main__':
    if len(sys.argv) != 3 or not sys.argv[1].isdigit() or int(sys.argv[1]) < 1:
        sys.exit(__doc__)
    many_cubes(int(sys.argv[1])).write_glb(sys.argv[2])
