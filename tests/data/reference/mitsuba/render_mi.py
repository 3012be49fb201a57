import sys, os, time, argparse, json
import numpy as np
import mitsuba as mi
mi.set_variant(os.environ.get('MI_VARIANT', 'llvm_ad_rgb'))
import drjit as dr
sys.path.insert(0, os.path.dirname(__file__))
import scenes

ap = argparse.ArgumentParser()
ap.add_argument('scene'); ap.add_argument('--frames', default='0')
ap.add_argument('--fps', type=float, default=24); ap.add_argument('--spp', type=int, default=1024)
ap.add_argument('--pass-spp', type=int, default=256); ap.add_argument('--seed', type=int, default=0)
ap.add_argument('--out', required=True); ap.add_argument('--name', default='frame_{frame:04d}')
ap.add_argument('--glb'); ap.add_argument('--size')
a = ap.parse_args()
fn, Wp, Hp = scenes.SCENES[a.scene]
if a.size: Wp, Hp = map(int, a.size.split('x'))
S = fn()
os.makedirs(a.out, exist_ok=True)
if a.glb: S.write_glb(a.glb)
frames = [int(f) for f in a.frames.split(',')]
for f in frames:
    t = f/a.fps
    t0 = time.time()
    d = S.mitsuba_dict(t, Wp, Hp, a.pass_spp, os.path.join(a.out, f'_ply_{a.scene}_{f}'))
    scene = mi.load_dict(d)
    acc = None
    npass = max(1, a.spp//a.pass_spp)
    for p in range(npass):
        img = np.array(mi.render(scene, spp=a.pass_spp, seed=a.seed*100003 + p*7919 + 1))
        acc = img if acc is None else acc+img
    img = (acc/npass).astype(np.float32)[:, :, :3]
    mi.Bitmap(img, mi.Bitmap.PixelFormat.RGB).write(os.path.join(a.out, a.name.format(frame=f)+'.exr'))
    print(json.dumps(dict(scene=a.scene, frame=f, t=t, spp=npass*a.pass_spp, seed=a.seed,
                          secs=round(time.time()-t0, 2), mean=float(img.mean()))), flush=True)
