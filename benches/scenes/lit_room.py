"""The room the moving-object bench scenes share: a closed box 2 m across
seen from inside, a ceiling panel light sliding 0.8 m over one second, and
a camera inside by the front wall (`turning_ball.py`, `many_cubes.py`).
Their objects go between `room` and `light_and_camera`, which keeps the
nodes in the order the scenes have always had (their files the same
bytes)."""
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, '..', '..', 'tests', 'data', 'reference', 'mitsuba'))
from gen import box  # noqa: E402
from scenes import oquad, look_at_quat  # noqa: E402


def room(S, white):
    """The room's walls, of material `white`: a box seen from inside
    (normals and winding turned in)."""
    P, N, I = box((0, 1, 0), (1, 1, 1))
    N = -N
    I = I.reshape(-1, 3)[:, ::-1].reshape(-1)
    S.node('room', mesh=S.mesh('room', [(P, N, I, 'u16', white)]))


def light_and_camera(S, light):
    """The sliding ceiling panel, of emissive material `light`, and the
    camera. Inside the room, by its front wall: from outside (z = 2.9,
    before 2026-12-04) the camera saw the closed room's unlit outside,
    black."""
    q = oquad([(-0.2, 1.98, -0.2), (0.2, 1.98, -0.2), (0.2, 1.98, 0.2), (-0.2, 1.98, 0.2)], (0, -1, 0))
    panel = S.node('light', mesh=S.mesh('light', [(*q, 'u16', light)]))
    S.anim(panel, 'translation', [0, 1], [(-0.4, 0, 0), (0.4, 0, 0)])
    eye = (0, 1, 0.95)
    S.node('camera', t=eye, r=look_at_quat(eye, (0, 0.5, 0)), camera=True)
    S.camera = dict(yfov=0.9, aspect=1.0, znear=0.05, zfar=100.0)
