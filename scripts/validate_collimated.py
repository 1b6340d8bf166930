#!/usr/bin/env python3
"""Validate SPPM's collimated area light (Mitsuba's `directionalarea`) against Mitsuba 3's
particle tracer on scenes/validation/collimated (docs/validation.md).

A collimated beam sends light along its surface normals only: no ray traced from the camera or
from a surface meets that direction, so path tracers render it black and only particles carry
it. This script renders the scene with Mitsuba's `ptracer` (llvm_ad_rgb, 4 chunks of
--ref-spp with distinct seeds, cached under out/validation/collimated/) and with our `render
--integrator sppm` at --passes, and compares the sharpest level `y` region by region: the
whole image, everything but the rough-glass sphere, the floor inside the beam, and the sphere
(whose highlight of the beam itself no visible point can gather: see docs/validation.md).

    python3 scripts/validate_collimated.py --bin target/release/render --passes 512
"""

import argparse
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from validate_pt import ROOT, mitsuba  # noqa: E402

SCENE = ROOT / "scenes" / "validation" / "collimated" / "scene.xml"
RES = 64
CHUNKS = 4
SPHERE = (np.array([0.0, 0.6, 0.0]), 0.5)


def reference(mi, spp, out):
    """Mitsuba's ptracer image chunks (cached per spp)."""
    cache = out / f"ptracer_{spp}x{CHUNKS}.npy"
    if cache.exists():
        return np.load(cache)
    scene = mi.load_file(str(SCENE), res=RES)
    integrator = mi.load_dict({"type": "ptracer", "max_depth": 8})
    chunks = np.stack([np.array(mi.render(scene, integrator=integrator, spp=spp, seed=s))[..., :3]
                       for s in range(CHUNKS)])
    np.save(cache, chunks)
    return chunks


def sphere_mask(mi):
    """Pixels whose camera ray first hits the glass sphere."""
    scene = mi.load_file(str(SCENE), res=RES)
    sensor = scene.sensors()[0]
    mask = np.zeros((RES, RES), bool)
    for y in range(RES):
        for x in range(RES):
            ray, _ = sensor.sample_ray(0, 0, mi.Point2f((x + 0.5) / RES, (y + 0.5) / RES), mi.Point2f(0.5))
            si = scene.ray_intersect(ray)
            if si.is_valid():
                p = np.array([si.p.x, si.p.y, si.p.z]).ravel()
                mask[y, x] = abs(np.linalg.norm(p - SPHERE[0]) - SPHERE[1]) < 1e-3
    return mask


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--bin", type=Path, default=ROOT / "target" / "release" / "render")
    ap.add_argument("--passes", type=int, default=512)
    ap.add_argument("--photons", type=int, default=100_000)
    ap.add_argument("--ref-spp", type=int, default=1024, help="Mitsuba ptracer spp per chunk")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "validation" / "collimated")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    mi = mitsuba()
    ref = reference(mi, args.ref_spp, args.out).mean(axis=0)
    prefix = args.out / "ours"
    subprocess.run([str(args.bin), str(SCENE), "--integrator", "sppm", "--photons", str(args.photons),
                    "--passes", str(args.passes), "--seed", "1", "-D", f"res={RES}", "--out", str(prefix)],
                   check=True, capture_output=True)
    bundle = dict(mi.Bitmap(str(args.out / f"ours_p{args.passes:04d}.exr")).split())
    ours = np.array(bundle["y"], dtype=np.float64)[..., :3]
    sphere = sphere_mask(mi)
    beam = (ref.mean(axis=-1) > 0.4) & ~sphere
    print(f"ours `sppm` {args.passes} passes x {args.photons} photons vs Mitsuba ptracer "
          f"{CHUNKS} x {args.ref_spp} spp, {RES}x{RES}")
    print("| region | pixels | mean RGB Mitsuba | mean RGB ours | ours / Mitsuba |")
    print("|---|---|---|---|---|")
    for name, m in (("whole image", np.ones_like(sphere)), ("all but the glass sphere", ~sphere),
                    ("floor inside the beam", beam), ("the glass sphere", sphere)):
        a, b = ref[m].mean(axis=0), ours[m].mean(axis=0)
        fmt = lambda v: ", ".join(f"{x:.4f}" for x in v)  # noqa: E731
        print(f"| {name} | {int(m.sum())} | {fmt(a)} | {fmt(b)} | {fmt(b / a)} |")


if __name__ == "__main__":
    main()
