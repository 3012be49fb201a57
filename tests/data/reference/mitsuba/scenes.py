import math, numpy as np
from gen import Scene, quad, merge, box, uv_sphere, deindex, axis_angle

def oquad(corners, want):
    P, N, I = quad(*corners)
    if np.dot(N[0], want) < 0:
        P, N, I = quad(*corners[::-1])
    return P, N, I

def qmul(a, b):
    x1, y1, z1, w1 = a; x2, y2, z2, w2 = b
    return [w1*x2+x1*w2+y1*z2-z1*y2, w1*y2-x1*z2+y1*w2+z1*x2,
            w1*z2+x1*y2-y1*x2+z1*w2, w1*w2-x1*x2-y1*y2-z1*z2]

def look_at_quat(eye, target, up=(0, 1, 0)):
    """rotation so that node -Z looks at target, +Y ~ up"""
    f = np.asarray(target, float)-np.asarray(eye, float); f /= np.linalg.norm(f)
    z = -f
    x = np.cross(up, z); x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z], 1)
    # matrix -> quaternion
    tr = R.trace()
    if tr > 0:
        s = math.sqrt(tr+1)*2
        w = 0.25*s; qx = (R[2, 1]-R[1, 2])/s; qy = (R[0, 2]-R[2, 0])/s; qz = (R[1, 0]-R[0, 1])/s
    else:
        i = int(np.argmax(np.diag(R)))
        if i == 0:
            s = math.sqrt(1+R[0, 0]-R[1, 1]-R[2, 2])*2
            w = (R[2, 1]-R[1, 2])/s; qx = 0.25*s; qy = (R[0, 1]+R[1, 0])/s; qz = (R[0, 2]+R[2, 0])/s
        elif i == 1:
            s = math.sqrt(1+R[1, 1]-R[0, 0]-R[2, 2])*2
            w = (R[0, 2]-R[2, 0])/s; qx = (R[0, 1]+R[1, 0])/s; qy = 0.25*s; qz = (R[1, 2]+R[2, 1])/s
        else:
            s = math.sqrt(1+R[2, 2]-R[0, 0]-R[1, 1])*2
            w = (R[1, 0]-R[0, 1])/s; qx = (R[0, 2]+R[2, 0])/s; qy = (R[1, 2]+R[2, 1])/s; qz = 0.25*s
    return [qx, qy, qz, w]

def hall(diffuse_only=False):
    S = Scene()
    H = 3.0
    m_floor = S.mat('floor', (0.70, 0.65, 0.55))
    m_ceil = S.mat('ceiling', (0.80, 0.80, 0.80))
    m_red = S.mat('red', (0.70, 0.15, 0.10))
    m_green = S.mat('green', (0.15, 0.60, 0.20))
    m_blue = S.mat('blue', (0.20, 0.30, 0.70))
    m_white = S.mat('white', (0.75, 0.75, 0.72))
    m_l1 = S.mat('light_warm', (0, 0, 0), emissive=(1.0, 0.85, 0.6), strength=6.0)
    m_l2 = S.mat('light_blue_2sided', (0, 0, 0), emissive=(0.3, 0.55, 1.0), double=True)
    m_plastic = S.mat('plastic', (0.10, 0.35, 0.80), metallic=0.0, roughness=1.0 if diffuse_only else 0.2)
    m_metal = S.mat('metal', (0.95, 0.75, 0.45), metallic=0.0 if diffuse_only else 1.0, roughness=1.0 if diffuse_only else 0.15)
    # L-shaped room: outline in xz
    outline = [(0, 0), (6, 0), (6, 3), (3, 3), (3, 6), (0, 6)]
    centre_main = np.array([1.5, 1.5, 1.5])
    floor = merge([oquad([(0, 0, 0), (6, 0, 0), (6, 0, 3), (0, 0, 3)], (0, 1, 0)),
                   oquad([(0, 0, 3), (3, 0, 3), (3, 0, 6), (0, 0, 6)], (0, 1, 0))])
    ceil = merge([oquad([(0, H, 0), (6, H, 0), (6, H, 3), (0, H, 3)], (0, -1, 0)),
                  oquad([(0, H, 3), (3, H, 3), (3, H, 6), (0, H, 6)], (0, -1, 0))])
    walls = {m_red: [], m_green: [], m_blue: [], m_white: []}
    wall_mats = [m_white, m_green, m_white, m_blue, m_white, m_red]
    inward = [(0, 0, 1), (-1, 0, 0), (0, 0, -1), (-1, 0, 0), (0, 0, -1), (1, 0, 0)]
    for k in range(6):
        (x0, z0), (x1, z1) = outline[k], outline[(k+1) % 6]
        walls[wall_mats[k]].append(oquad([(x0, 0, z0), (x1, 0, z1), (x1, H, z1), (x0, H, z0)], inward[k]))
    prims = [deindex(*floor) + (None, m_floor), deindex(*ceil) + (None, m_ceil)]
    for m, qs in walls.items():
        prims.append(deindex(*merge(qs)) + (None, m))
    room = S.mesh('room', prims)            # non-indexed, multi-primitive
    S.node('room', mesh=room)
    # light 1: one-sided, facing down, strength 6, u16 indices
    P, N, I = oquad([(4.0, 2.98, 1.0), (5.0, 2.98, 1.0), (5.0, 2.98, 2.0), (4.0, 2.98, 2.0)], (0, -1, 0))
    l1 = S.mesh('light1', [(P, N, I, 'u16', m_l1)])
    S.node('light1', mesh=l1)
    # light 2: doubleSided, front faces -z (towards wall z=0); camera sees its back
    P, N, I = oquad([(1.0, 0.8, 0.6), (2.2, 0.8, 0.6), (2.2, 1.8, 0.6), (1.0, 1.8, 0.6)], (0, 0, -1))
    l2 = S.mesh('light2', [(P, N, I, 'u16', m_l2)])
    S.node('light2', mesh=l2)
    # metal sphere, u16 indices
    P, N, I = uv_sphere((0, 0, 0), 0.5, 32, 16)
    sph = S.mesh('metal_sphere', [(P, N, I, 'u16', m_metal)])
    S.node('sphere', t=(1.8, 0.5, 2.0), mesh=sph)
    # animated hierarchy: parent (rotation + non-uniform scale, LINEAR translation keys)
    P, N, I = box((0, 0, 0), (0.35, 0.35, 0.35))
    bx = S.mesh('plastic_box', [(P, N, I, 'u32', m_plastic)])
    child = S.node('tumbler', t=(0, 0.9, 0), mesh=bx, root=False)
    parent = S.node('rig', t=(4.0, 0.0, 2.0), r=axis_angle((0, 1, 0), math.radians(30)),
                    s=(1.4, 0.8, 1.0), children=[child])
    S.anim(parent, 'translation', [0.0, 0.37, 0.9], [(4.0, 0.0, 2.0), (3.2, 0.0, 1.2), (4.6, 0.2, 1.0)])
    q0 = [0, 0, 0, 1]
    q1 = axis_angle((0.3, 1.0, 0.2), math.radians(170))
    q2 = qmul(q1, axis_angle((1, 0, 0), math.radians(120)))
    S.anim(child, 'rotation', [0.0, 0.37, 0.9], [q0, q1, q2])
    # camera
    eye = (5.8, 1.7, 2.8)
    S.node('camera', t=eye, r=look_at_quat(eye, (1.5, 0.8, 2.4)), camera=True)
    S.camera = dict(yfov=0.8, aspect=1.6, znear=0.05, zfar=100.0)
    return S

def lightmove():
    S = Scene()
    m_white = S.mat('white', (0.75, 0.75, 0.75))
    m_red = S.mat('red', (0.75, 0.2, 0.15))
    m_green = S.mat('green', (0.2, 0.7, 0.25))
    m_yel = S.mat('yellow', (0.8, 0.75, 0.2))
    m_l = S.mat('light', (0, 0, 0), emissive=(1.0, 0.9, 0.7), strength=10.0)
    X, Y, Z = 4.0, 3.0, 4.0
    c = (X/2, Y/2, Z/2)
    def face(corners, m):
        cen = np.mean(np.array(corners, float), 0)
        return oquad(corners, np.array(c)-cen)
    white = merge([face([(0, 0, 0), (X, 0, 0), (X, 0, Z), (0, 0, Z)], 0),
                   face([(0, Y, 0), (X, Y, 0), (X, Y, Z), (0, Y, Z)], 0),
                   face([(0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)], 0),
                   face([(0, 0, Z), (X, 0, Z), (X, Y, Z), (0, Y, Z)], 0)])
    red = face([(0, 0, 0), (0, 0, Z), (0, Y, Z), (0, Y, 0)], 0)
    green = face([(X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)], 0)
    room = S.mesh('room', [white + ('u16', m_white), red + ('u32', m_red), deindex(*green) + (None, m_green)])
    S.node('room', mesh=room)
    P, N, I = oquad([(-0.4, -0.3, 0), (0.4, -0.3, 0), (0.4, 0.3, 0), (-0.4, 0.3, 0)], (0, 0, 1))
    lm = S.mesh('light', [(P, N, I, 'u16', m_l)])
    ln = S.node('light', t=(0.8, 2.2, 0.01), mesh=lm)
    S.anim(ln, 'translation', [0.0, 0.5, 1.0], [(0.8, 2.2, 0.01), (3.2, 1.6, 0.01), (2.0, 2.4, 0.01)])
    P, N, I = uv_sphere((0, 0, 0), 0.35, 24, 12)
    sm = S.mesh('ball', [(P, N, I, 'u16', m_yel)])
    sn = S.node('ball', t=(0.6, 0.4, 1.5), mesh=sm)
    S.anim(sn, 'translation', [0.0, 0.5, 1.0], [(0.6, 0.4, 1.5), (3.4, 1.2, 2.0), (0.6, 0.4, 2.5)])
    P, N, I = box((0, 0, 0), (0.4, 0.8, 0.4))
    bm = S.mesh('pillar', [(P, N, I, 'u32', m_white)])
    S.node('pillar', t=(2.6, 0.8, 1.2), r=axis_angle((0, 1, 0), 0.5), mesh=bm)
    eye = (2.0, 1.5, 3.9)
    S.node('camera', t=eye, r=look_at_quat(eye, (2.0, 1.2, 0.0)), camera=True)
    S.camera = dict(yfov=0.9, aspect=0.75, znear=0.05, zfar=50.0)
    return S

SCENES = {'hall': (hall, 96, 60), 'lightmove': (lightmove, 48, 64), 'hall_diffuse': (lambda: hall(True), 96, 60)}

def mini(variant):
    """simple closed room + ceiling light + one test object"""
    S = Scene()
    m_white = S.mat('white', (0.75, 0.75, 0.75))
    m_red = S.mat('red', (0.75, 0.2, 0.15))
    m_green = S.mat('green', (0.2, 0.7, 0.25))
    m_l = S.mat('light', (0, 0, 0), emissive=(1.0, 1.0, 1.0), strength=10.0)
    X, Y, Z = 4.0, 3.0, 4.0
    c = (X/2, Y/2, Z/2)
    def face(corners):
        cen = np.mean(np.array(corners, float), 0)
        return oquad(corners, np.array(c)-cen)
    white = merge([face([(0, 0, 0), (X, 0, 0), (X, 0, Z), (0, 0, Z)]),
                   face([(0, Y, 0), (X, Y, 0), (X, Y, Z), (0, Y, Z)]),
                   face([(0, 0, 0), (X, 0, 0), (X, Y, 0), (0, Y, 0)]),
                   face([(0, 0, Z), (X, 0, Z), (X, Y, Z), (0, Y, Z)])])
    red = face([(0, 0, 0), (0, 0, Z), (0, Y, Z), (0, Y, 0)])
    green = face([(X, 0, 0), (X, 0, Z), (X, Y, Z), (X, Y, 0)])
    room = S.mesh('room', [white + ('u32', m_white), red + ('u32', m_red), green + ('u32', m_green)])
    S.node('room', mesh=room)
    P, N, I = oquad([(1.5, 2.98, 1.5), (2.5, 2.98, 1.5), (2.5, 2.98, 2.5), (1.5, 2.98, 2.5)], (0, -1, 0))
    S.node('light', mesh=S.mesh('light', [(P, N, I, 'u32', m_l)]))
    kind = variant.split(':')
    if kind[0] == 'shear_diffuse':     # diffuse cube under rotated + non-uniformly scaled parent
        m = S.mat('obj', (0.8, 0.8, 0.8))
        P, N, I = box((0, 0, 0), (0.35, 0.35, 0.35))
        ch = S.node('child', t=(0, 0.9, 0), r=axis_angle((0.3, 1.0, 0.2), math.radians(50)),
                    mesh=S.mesh('b', [(P, N, I, 'u32', m)]), root=False)
        S.node('rig', t=(2.0, 0.0, 2.0), r=axis_angle((0, 1, 0), math.radians(30)), s=(1.4, 0.8, 1.0), children=[ch])
    elif kind[0] == 'rot_diffuse':     # same, uniform scale (control)
        m = S.mat('obj', (0.8, 0.8, 0.8))
        P, N, I = box((0, 0, 0), (0.35, 0.35, 0.35))
        ch = S.node('child', t=(0, 0.9, 0), r=axis_angle((0.3, 1.0, 0.2), math.radians(50)),
                    mesh=S.mesh('b', [(P, N, I, 'u32', m)]), root=False)
        S.node('rig', t=(2.0, 0.0, 2.0), r=axis_angle((0, 1, 0), math.radians(30)), children=[ch])
    elif kind[0] in ('metal_sphere', 'plastic_sphere', 'diffuse_sphere'):
        rough = float(kind[1])
        met = 1.0 if kind[0] == 'metal_sphere' else 0.0
        base = (0.95, 0.75, 0.45) if met else (0.10, 0.35, 0.80)
        if len(kind) > 2: base = tuple(float(x) for x in kind[2].split(','))
        m = S.mat('obj', base, metallic=met, roughness=rough)
        P, N, I = uv_sphere((0, 0, 0), 0.6, 32, 16)
        S.node('sph', t=(2.0, 0.6, 2.0), mesh=S.mesh('s', [(P, N, I, 'u16', m)]))
    elif kind[0] in ('slerp_neg', 'slerp_pos'):
        m = S.mat('obj', (0.8, 0.8, 0.8))
        P, N, I = box((0, 0, 0), (0.5, 0.25, 0.35))
        nd = S.node('bx', t=(2.0, 0.9, 2.0), mesh=S.mesh('b', [(P, N, I, 'u32', m)]))
        q1 = axis_angle((0.3, 1.0, 0.2), math.radians(170))
        if kind[0] == 'slerp_neg': q1 = [-x for x in q1]
        S.anim(nd, 'rotation', [0.0, 0.37], [[0, 0, 0, 1], q1])
    elif kind[0] in ('plastic_box', 'metal_box'):
        rough = float(kind[1])
        met = 1.0 if kind[0] == 'metal_box' else 0.0
        m = S.mat('obj', (0.95, 0.75, 0.45) if met else (0.10, 0.35, 0.80), metallic=met, roughness=rough)
        P, N, I = box((0, 0, 0), (0.5, 0.5, 0.5))
        S.node('bx', t=(2.0, 0.5, 2.0), r=axis_angle((0, 1, 0), 0.6), mesh=S.mesh('b', [(P, N, I, 'u32', m)]))
    eye = (2.0, 1.8, 3.9)
    S.node('camera', t=eye, r=look_at_quat(eye, (2.0, 0.8, 1.5)), camera=True)
    S.camera = dict(yfov=0.9, aspect=1.0, znear=0.05, zfar=50.0)
    return S
