#!/usr/bin/env python3
"""Print the Mitsuba 3 values that `renderer/src/bsdf/bumpmap.rs`'s `matches_mitsuba_values` test
compares against (pasted into the test):
the bitmap's eval_1_grad and bumpmap's eval (f*cos) and pdf on a 3x2 height field at one shading
point with sheared surface derivatives (needs `pip install mitsuba`; development only).

    python3 renderer/tests/data/bumpmap_reference.py
"""
import numpy as np, mitsuba as mi
mi.set_variant("scalar_rgb")
import drjit as dr
h = np.array([[0.4, 0.1, 0.25], [0.6, 0.3, 0.9]], dtype=np.float32).reshape(2, 3, 1)
def make(nested, scale=1.0, flip=True, shadow=True):
    return mi.load_dict({'type': 'bumpmap', 'scale': scale, 'flip_invalid_normals': flip,
        'use_shadowing_function': shadow,
        'h': {'type': 'bitmap', 'bitmap': mi.Bitmap(h), 'raw': True, 'filter_type': 'bilinear'},
        'bsdf': nested})
si = dr.zeros(mi.SurfaceInteraction3f)
si.uv = mi.Point2f(0.3, 0.7)
si.n = mi.Normal3f(0, 0, 1)
si.sh_frame = mi.Frame3f(mi.Vector3f(1,0,0), mi.Vector3f(0,1,0), mi.Vector3f(0,0,1))
si.dp_du = mi.Vector3f(2.0, 0.0, 0.0)
si.dp_dv = mi.Vector3f(0.5, 1.5, 0.0)
tex = mi.load_dict({'type': 'bitmap', 'bitmap': mi.Bitmap(h), 'raw': True, 'filter_type': 'bilinear'})
print("grad", tex.eval_1_grad(si), "val", tex.eval_1(si))
ctx = mi.BSDFContext()
cases = [("diffuse", {'type': 'diffuse', 'reflectance': 0.5}, 2.5, True, True),
         ("roughconductor", {'type': 'roughconductor', 'distribution': 'ggx', 'alpha': 0.3}, 1.0, True, True),
         ("diffuse noflip noshadow", {'type': 'diffuse', 'reflectance': 0.5}, -3.0, False, False)]
wos = [mi.Vector3f(0.2, 0.1, 0.97), mi.Vector3f(-0.7, 0.3, 0.4)]
wis = [mi.Vector3f(0, 0, 1), mi.Vector3f(0.5, -0.2, 0.8), mi.Vector3f(-0.6, 0.0, 0.8), mi.Vector3f(0.1, 0.9, 0.3), mi.Vector3f(0.95, 0.1, 0.15)]
for name, nested, scale, flip, shadow in cases:
    b = make(nested, scale, flip, shadow)
    for wo in wos:
        wo = dr.normalize(wo)
        si.wi = wo
        for wi in wis:
            wi = dr.normalize(wi)
            v = b.eval(ctx, si, wi); p = b.pdf(ctx, si, wi)
            print(f'("{name}", {scale}, {str(flip).lower()}, {str(shadow).lower()}, [{wo[0]:.7f}, {wo[1]:.7f}, {wo[2]:.7f}], [{wi[0]:.7f}, {wi[1]:.7f}, {wi[2]:.7f}], {v[0]:.7e}, {p:.7e}),')
