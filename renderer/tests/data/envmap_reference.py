#!/usr/bin/env python3
"""Generate `envmap_reference.json` (next to this script): radiance that Mitsuba 3's `envmap`
emitter returns for escaping directions, which the envmap test (`radiance_matches_mitsuba` in
`renderer/src/lights/envmap.rs`) compares against (lookup convention, texel centres,
wrap-around, poles, `scale`, `to_world`).

The map is a formula (so the test builds the same texels without an image file): a 7x5 image,
texel (x, y) = (1 + x + 0.1 y, 2 + 0.5 y + 0.05 x, 0.3 + 0.2 x y).

Every number is an f32 value, written exactly: the shortest decimal of its f64 value, which
reads back to the same f32 (see `reference_json.py`).

Usage (needs `pip install mitsuba`; development only, never a runtime dependency):
    python3 renderer/tests/data/envmap_reference.py > renderer/tests/data/envmap_reference.json
"""
import os
import sys
import tempfile

import numpy as np
import mitsuba as mi

from reference_json import f32, f32s, write_json

mi.set_variant("scalar_rgb")
W, H = 7, 5


def texel(x, y):
    return [1 + x + 0.1 * y, 2 + 0.5 * y + 0.05 * x, 0.3 + 0.2 * x * y]


img = np.array([[texel(x, y) for x in range(W)] for y in range(H)], dtype=np.float32)
path = os.path.join(tempfile.mkdtemp(), "envmap_reference.exr")
mi.Bitmap(img).write(path)

rng = np.random.default_rng(20261123)
dirs = list(rng.normal(size=(48, 3)))
# The poles, the -z seam (between the last and the first column), the axes.
dirs += [[0, 1, 0], [0, -1, 0], [0, 0, -1], [0, 0, 1], [1, 0, 0], [-1, 0, 0],
         [1e-3, -1, 2e-3], [0.01, 0.3, -1]]
dirs = [np.asarray(d, np.float64) / np.linalg.norm(d) for d in dirs]
# (scale, rotation about +y in degrees)
CASES = [(1.0, 0.0), (2.5, 0.0), (1.0, 90.0)]


def reference_json(version, size, cases, values):
    """The JSON document's fields, in order."""
    return [
        ("about", f"Radiance of Mitsuba 3's envmap emitter ({version}, scalar_rgb) for the envmap "
                  "test; written by envmap_reference.py in this folder, do not edit by hand. "
                  "Numbers are f32 values written exactly."),
        # Image width and height of the test map (texels by the formula in the generator).
        ("size", list(size)),
        # Scale, and rotation of `to_world` about +y in degrees, of each case.
        ("cases", [{"scale": f32(s), "degrees": f32(a)} for s, a in cases]),
        # Escaping ray direction and the radiance seen along it.
        ("values", [{"case": c, "direction": f32s(d), "radiance": f32s(v)} for c, d, v in values]),
    ]


values = []
for case, (scale, angle) in enumerate(CASES):
    desc = {"type": "envmap", "filename": path, "scale": scale}
    if angle:
        desc["to_world"] = mi.ScalarTransform4f().rotate([0, 1, 0], angle)
    em = mi.load_dict(desc)
    for d in dirs:
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d))
        v = np.array(em.eval(si))
        values.append((case, d, v[:3]))
write_json(sys.stdout, reference_json(mi.__version__, (W, H), CASES, values))
