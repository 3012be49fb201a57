#!/usr/bin/env python3
"""A glTF scene where many triangles move under a moving light: a closed
room 2 m across, a UV sphere of N * (N - 2) triangles (radius 0.35 m)
turning about its vertical axis, a block sliding on the floor, and a
ceiling panel light sliding 0.8 m, all over one second (24 frames at
24 fps). Every frame moves the sphere's triangles and the light, so
`trc` evaluates its records' direct light at t0+1 and at the later frames
its records check, the moving triangles traced in each of those frames
(`benches/RESULTS.md`, "What these checks find once", "The moving objects
traced as instances").

    python3 benches/scenes/turning_ball.py N OUT.glb

N = 1024 gives 1,046,528 triangles in the sphere. Needs numpy (the scene
writer in tests/data/reference/mitsuba/ is used).
"""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..', '..', 'tests', 'data', 'reference', 'mitsuba'))
from gen import Scene, box, uv_sphere, axis_angle  # noqa: E402
from lit_room import room, light_and_camera  # noqa: E402


def turning_ball(n):
    S = Scene()
    white = S.mat('white', (0.7, 0.7, 0.7))
    red = S.mat('red', (0.7, 0.1, 0.1))
    green = S.mat('green', (0.1, 0.6, 0.1))
    light = S.mat('light', (0, 0, 0), emissive=(1, 1, 1), strength=20.0)
    room(S, white)
    P, N, I = uv_sphere((0, 0, 0), 0.35, n, n // 2)
    ball = S.node('ball', t=(0.2, 0.35, 0.0), mesh=S.mesh('ball', [(P, N, I, 'u32', red)]))
    S.anim(ball, 'rotation', [0, 1], [axis_angle((0, 1, 0), 0), axis_angle((0, 1, 0), 3.0)])
    P, N, I = box((0, 0, 0), (0.15, 0.3, 0.15))
    block = S.node('block', t=(-0.5, 0.3, -0.3), mesh=S.mesh('block', [(P, N, I, 'u16', green)]))
    S.anim(block, 'translation', [0, 1], [(-0.5, 0.3, -0.3), (-0.2, 0.3, 0.3)])
    light_and_camera(S, light)
    return S


if __name__ == '__main__':
    if len(sys.argv) != 3 or not sys.argv[1].isdigit() or int(sys.argv[1]) < 4:
        sys.exit(__doc__)
    turning_ball(int(sys.argv[1])).write_glb(sys.argv[2])
