"""Parametric scene -> (a) glTF 2.0 .glb  (b) Mitsuba 3 scene dict at time t.

Independent of radcache. Conventions per glTF 2.0 spec:
 node matrix = T * R * S, quaternion (x,y,z,w), camera looks down -Z, +Y up,
 LINEAR interpolation: lerp for translation/scale, slerp for rotation (spec
 Appendix C), times clamped to the first/last key.
"""
import json, struct, os, math
import numpy as np

# ---------------------------------------------------------------- math
def quat_to_mat(q):
    x, y, z, w = q
    n = math.sqrt(x*x+y*y+z*z+w*w); x, y, z, w = x/n, y/n, z/n, w/n
    return np.array([
        [1-2*(y*y+z*z), 2*(x*y-z*w),   2*(x*z+y*w)],
        [2*(x*y+z*w),   1-2*(x*x+z*z), 2*(y*z-x*w)],
        [2*(x*z-y*w),   2*(y*z+x*w),   1-2*(x*x+y*y)]])

def axis_angle(axis, ang):
    a = np.asarray(axis, float); a = a/np.linalg.norm(a)
    s = math.sin(ang/2)
    return [a[0]*s, a[1]*s, a[2]*s, math.cos(ang/2)]

def trs(t, r, s):
    M = np.eye(4)
    M[:3, :3] = quat_to_mat(r) @ np.diag(s)
    M[:3, 3] = t
    return M

def slerp(a, b, u):
    a = np.asarray(a, float); b = np.asarray(b, float)
    d = float(np.dot(a, b))
    # glTF spec Appendix C: a = acos(|d|), s = d/|d|
    sgn = 1.0 if d >= 0 else -1.0
    ad = min(abs(d), 1.0)
    ang = math.acos(ad)
    if ang < 1e-9:
        return list(a)
    r = (math.sin(ang*(1-u))/math.sin(ang))*a + sgn*(math.sin(ang*u)/math.sin(ang))*b
    return list(r)

def sample_channel(times, values, path, t, interp='LINEAR'):
    times = list(times)
    if t <= times[0]:
        return list(values[0])
    if t >= times[-1]:
        return list(values[-1])
    for k in range(len(times)-1):
        if times[k] <= t <= times[k+1]:
            u = (t-times[k])/(times[k+1]-times[k])
            if interp == 'STEP':
                return list(values[k])
            if path == 'rotation':
                return slerp(values[k], values[k+1], u)
            return list((1-u)*np.asarray(values[k]) + u*np.asarray(values[k+1]))
    raise RuntimeError

# ---------------------------------------------------------------- geometry helpers
def quad(p0, p1, p2, p3):
    """CCW quad (seen from front); returns positions(4), normals(4), indices(6)."""
    P = np.array([p0, p1, p2, p3], float)
    n = np.cross(P[1]-P[0], P[2]-P[0]); n /= np.linalg.norm(n)
    return P, np.tile(n, (4, 1)), np.array([0, 1, 2, 0, 2, 3])

def merge(parts):
    P, N, I = [], [], []
    off = 0
    for p, n, i in parts:
        P.append(p); N.append(n); I.append(i+off); off += len(p)
    return np.concatenate(P), np.concatenate(N), np.concatenate(I)

def box(c, h):
    """axis-aligned box centre c half-size h, outward normals, flat."""
    c = np.asarray(c, float); h = np.asarray(h, float)
    parts = []
    for ax in range(3):
        for sg in (-1, 1):
            u = (ax+1) % 3; v = (ax+2) % 3
            corners = []
            for (a, b) in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = np.zeros(3); p[ax] = sg; p[u] = a; p[v] = b
                corners.append(c + p*h)
            if sg < 0:
                corners = corners[::-1]
            parts.append(quad(*corners))
    return merge(parts)

def uv_sphere(c, r, nu=32, nv=16):
    P, N = [], []
    for j in range(nv+1):
        th = math.pi*j/nv
        for i in range(nu+1):
            ph = 2*math.pi*i/nu
            n = np.array([math.sin(th)*math.cos(ph), math.cos(th), -math.sin(th)*math.sin(ph)])
            P.append(np.asarray(c)+r*n); N.append(n)
    I = []
    for j in range(nv):
        for i in range(nu):
            a = j*(nu+1)+i; b = a+nu+1
            # outward CCW
            if j != 0:
                I += [a, b, a+1]
            if j != nv-1:
                I += [a+1, b, b+1]
    P = np.array(P); N = np.array(N); I = np.array(I)
    # check orientation
    t0 = I[:3]
    fn = np.cross(P[t0[1]]-P[t0[0]], P[t0[2]]-P[t0[0]])
    if np.dot(fn, N[t0[0]]+N[t0[1]]+N[t0[2]]) < 0:
        I = I.reshape(-1, 3)[:, ::-1].reshape(-1)
    return P, N, I

def deindex(P, N, I):
    return P[I], N[I], None

# ---------------------------------------------------------------- scene container
class Scene:
    def __init__(self):
        self.materials = []; self.meshes = []; self.nodes = []; self.roots = []
        self.anims = []; self.camera = None
    def mat(self, name, base=(0.8, 0.8, 0.8), metallic=0.0, roughness=1.0,
            emissive=(0, 0, 0), strength=None, double=False):
        self.materials.append(dict(name=name, base=base, metallic=metallic, roughness=roughness,
                                   emissive=emissive, strength=strength, double=double))
        return len(self.materials)-1
    def mesh(self, name, prims):
        """prims: list of (P, N, I or None, index_type 'u16'|'u32'|None, mat)"""
        self.meshes.append(dict(name=name, prims=prims)); return len(self.meshes)-1
    def node(self, name, t=(0, 0, 0), r=(0, 0, 0, 1), s=(1, 1, 1), mesh=None, camera=False,
             children=(), root=True):
        self.nodes.append(dict(name=name, t=list(t), r=list(r), s=list(s), mesh=mesh,
                               camera=camera, children=list(children)))
        i = len(self.nodes)-1
        if root:
            self.roots.append(i)
        return i
    def anim(self, node, path, times, values, interp='LINEAR'):
        self.anims.append(dict(node=node, path=path, times=list(times),
                               values=[list(v) for v in values], interp=interp))

    # ------------------------------------------------ evaluation
    def world_mats(self, t):
        local = []
        for i, n in enumerate(self.nodes):
            T, R, S = n['t'], n['r'], n['s']
            for a in self.anims:
                if a['node'] == i:
                    v = sample_channel(a['times'], a['values'], a['path'], t, a['interp'])
                    if a['path'] == 'translation': T = v
                    elif a['path'] == 'rotation': R = v
                    elif a['path'] == 'scale': S = v
            local.append(trs(T, R, S))
        W = [None]*len(self.nodes)
        def rec(i, M):
            W[i] = M @ local[i]
            for c in self.nodes[i]['children']:
                rec(c, W[i])
        for r in self.roots:
            rec(r, np.eye(4))
        return W

    # ------------------------------------------------ glTF writer
    def write_glb(self, path):
        binbuf = bytearray(); views = []; accs = []
        def add_view(data, target=None):
            while len(binbuf) % 4: binbuf.append(0)
            off = len(binbuf); binbuf.extend(data)
            v = dict(buffer=0, byteOffset=off, byteLength=len(data))
            if target: v['target'] = target
            views.append(v); return len(views)-1
        def add_acc(arr, ctype, typ, target=None, minmax=False):
            arr = np.asarray(arr)
            fmt = {5126: '<f4', 5123: '<u2', 5125: '<u4'}[ctype]
            a = arr.astype(fmt)
            bv = add_view(a.tobytes(), target)
            ncomp = {'SCALAR': 1, 'VEC3': 3, 'VEC4': 4}[typ]
            acc = dict(bufferView=bv, componentType=ctype, count=int(a.size//ncomp), type=typ)
            if minmax:
                r = a.reshape(-1, ncomp)
                acc['min'] = [float(x) for x in r.min(0)]; acc['max'] = [float(x) for x in r.max(0)]
            accs.append(acc); return len(accs)-1
        jm = []
        for m in self.materials:
            d = dict(name=m['name'], pbrMetallicRoughness=dict(
                baseColorFactor=list(m['base'])+[1.0], metallicFactor=m['metallic'],
                roughnessFactor=m['roughness']))
            if any(e > 0 for e in m['emissive']): d['emissiveFactor'] = list(m['emissive'])
            if m['strength'] is not None:
                d['extensions'] = {'KHR_materials_emissive_strength': {'emissiveStrength': m['strength']}}
            if m['double']: d['doubleSided'] = True
            jm.append(d)
        jmesh = []
        for me in self.meshes:
            prims = []
            for (P, N, I, it, mat) in me['prims']:
                pa = add_acc(np.asarray(P, np.float32), 5126, 'VEC3', 34962, True)
                na = add_acc(np.asarray(N, np.float32), 5126, 'VEC3', 34962)
                pr = dict(attributes=dict(POSITION=pa, NORMAL=na), material=mat, mode=4)
                if I is not None:
                    pr['indices'] = add_acc(I, 5123 if it == 'u16' else 5125, 'SCALAR', 34963)
                prims.append(pr)
            jmesh.append(dict(name=me['name'], primitives=prims))
        jn = []
        for n in self.nodes:
            d = dict(name=n['name'])
            if n['t'] != [0, 0, 0]: d['translation'] = n['t']
            if n['r'] != [0, 0, 0, 1]: d['rotation'] = n['r']
            if n['s'] != [1, 1, 1]: d['scale'] = n['s']
            if n['mesh'] is not None: d['mesh'] = n['mesh']
            if n['camera']: d['camera'] = 0
            if n['children']: d['children'] = n['children']
            jn.append(d)
        janims = []
        if self.anims:
            samplers, channels = [], []
            for a in self.anims:
                ia = add_acc(np.array(a['times'], np.float32), 5126, 'SCALAR', None, True)
                oa = add_acc(np.array(a['values'], np.float32), 5126,
                             'VEC4' if a['path'] == 'rotation' else 'VEC3')
                samplers.append(dict(input=ia, output=oa, interpolation=a['interp']))
                channels.append(dict(sampler=len(samplers)-1, target=dict(node=a['node'], path=a['path'])))
            janims.append(dict(name='anim', samplers=samplers, channels=channels))
        c = self.camera
        persp = dict(yfov=c['yfov'], znear=c['znear'], zfar=c['zfar'])
        if c.get('aspect') is not None: persp['aspectRatio'] = c['aspect']
        J = dict(asset=dict(version='2.0', generator='mitsuba_check gen.py'),
                 scene=0, scenes=[dict(nodes=self.roots)], nodes=jn, meshes=jmesh,
                 materials=jm, cameras=[dict(type='perspective', perspective=persp)],
                 accessors=accs, bufferViews=views)
        if janims: J['animations'] = janims
        if any(m['strength'] is not None for m in self.materials):
            J['extensionsUsed'] = ['KHR_materials_emissive_strength']
        while len(binbuf) % 4: binbuf.append(0)
        J['buffers'] = [dict(byteLength=len(binbuf))]
        js = json.dumps(J).encode()
        while len(js) % 4: js += b' '
        total = 12 + 8 + len(js) + 8 + len(binbuf)
        with open(path, 'wb') as f:
            f.write(struct.pack('<III', 0x46546C67, 2, total))
            f.write(struct.pack('<II', len(js), 0x4E4F534A)); f.write(js)
            f.write(struct.pack('<II', len(binbuf), 0x004E4942)); f.write(binbuf)

    # ------------------------------------------------ Mitsuba
    def mitsuba_dict(self, t, W_px, H_px, spp, tmpdir, max_depth=-1):
        os.makedirs(tmpdir, exist_ok=True)
        W = self.world_mats(t)
        d = {'type': 'scene',
             'integrator': {'type': 'path', 'max_depth': max_depth},
             }
        k = 0
        for ni, n in enumerate(self.nodes):
            if n['mesh'] is None: continue
            M = W[ni]; A = M[:3, :3]; Nm = np.linalg.inv(A).T
            det = np.linalg.det(A)
            for (P, N, I, it, mat) in self.meshes[n['mesh']]['prims']:
                P = np.asarray(P, float); N = np.asarray(N, float)
                if I is None: I = np.arange(len(P))
                F = np.asarray(I).reshape(-1, 3)
                if det < 0: F = F[:, ::-1]   # glTF: negative determinant flips front face
                Pw = P @ A.T + M[:3, 3]
                Nw = N @ Nm.T; Nw /= np.linalg.norm(Nw, axis=1, keepdims=True)
                m = self.materials[mat]
                em = np.array(m['emissive'])*(1.0 if m['strength'] is None else m['strength'])
                shapes = [(Pw, Nw, F, True)]
                if em.max() > 0 and m['double']:
                    # back side: reversed copy offset by 1e-4 behind the surface
                    shapes.append((Pw - Nw*1e-4, -Nw, F[:, ::-1], True))
                for (pp, nn, ff, emit) in shapes:
                    fn = os.path.join(tmpdir, f'shape{k}.ply')
                    write_ply(fn, pp, nn, ff)
                    sd = {'type': 'ply', 'filename': fn, 'face_normals': False,
                          'bsdf': bsdf_of(m)}
                    if em.max() > 0:
                        sd['emitter'] = {'type': 'area', 'radiance': {'type': 'rgb', 'value': [float(x) for x in em]}}
                    d[f'shape{k}'] = sd; k += 1
        # camera
        ci = [i for i, n in enumerate(self.nodes) if n['camera']][0]
        C = W[ci] @ np.diag([-1.0, 1.0, -1.0, 1.0])
        c = self.camera
        import mitsuba as mi
        d['sensor'] = {'type': 'perspective', 'fov': math.degrees(c['yfov']), 'fov_axis': 'y',
                       'near_clip': c['znear'], 'far_clip': c['zfar'],
                       'to_world': mi.ScalarTransform4f(C.tolist()),
                       'sampler': {'type': 'independent', 'sample_count': spp},
                       'film': {'type': 'hdrfilm', 'width': W_px, 'height': H_px,
                                'rfilter': {'type': 'box'}, 'pixel_format': 'rgb',
                                'component_format': 'float32'}}
        return d

def bsdf_of(m):
    base = [float(x) for x in m['base']]
    if m['roughness'] >= 0.3:
        b = {'type': 'diffuse', 'reflectance': {'type': 'rgb', 'value': base}}
    elif m['metallic'] >= 0.5:
        b = {'type': 'roughconductor', 'material': 'none', 'distribution': 'ggx',
             'alpha': max(m['roughness']**2, 0.001),
             'specular_reflectance': {'type': 'rgb', 'value': base}}
    else:
        b = {'type': 'roughplastic', 'distribution': 'ggx', 'alpha': max(m['roughness']**2, 0.001),
             'int_ior': 1.5, 'diffuse_reflectance': {'type': 'rgb', 'value': base},
             'specular_reflectance': 1.0}
    return {'type': 'twosided', 'bsdf': b}

def write_ply(fn, P, N, F):
    P = np.asarray(P, np.float32); N = np.asarray(N, np.float32); F = np.asarray(F, np.int32)
    hdr = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(P)}\n"
           "property float x\nproperty float y\nproperty float z\n"
           "property float nx\nproperty float ny\nproperty float nz\n"
           f"element face {len(F)}\nproperty list uchar int vertex_indices\nend_header\n")
    vert = np.concatenate([P, N], 1).astype('<f4')
    fa = np.zeros(len(F), dtype=[('n', 'u1'), ('i', '<i4', 3)])
    fa['n'] = 3; fa['i'] = F
    with open(fn, 'wb') as f:
        f.write(hdr.encode()); f.write(vert.tobytes()); f.write(fa.tobytes())
