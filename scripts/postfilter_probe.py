#!/usr/bin/env python3
"""Probe: would a screen-space filter of the *output* close the gap to OIDN?

For every frozen held-out scene (scenes/heldout) it reconstructs the dataset's largest-pass
bundle of seed 0 with `infer`, then measures, as relMSE ÷ the bundle's best input level against
the frozen converged reference:

- `out`: the reconstruction as shipped (its photon-free part, direct-filtered or not, is
  what the filters below leave as it is);
- `s{σ}v4r2`, `s{σ}vyr2`, `s{σ}norange`: the output filtered by the screen filter's
  cross-bilateral (model/src/screen_filter.rs: same guide tolerances and range term; the
  photon-free part left unfiltered) at σ = 1, 2, 3 px, the range term reading z̃4's or ỹ's
  variance (strength 2), or no range term;
- `oidn_out`, `oidn_y`: OIDN 2.5 (inconsistent, the peer) on the output and on ỹ;
- `low2`, `low4`: the share of the output's relMSE left after blurring its error with a
  Gaussian of σ = 2 or 4 px (small: the error is pixel-scale noise, not blotches);
- `oracle{b}`: an upper bound for a *learned* per-pixel choice of filter: in every b×b block
  the candidate (the output itself and the bilaterals above) with the least error against the
  reference — what a network that picked the right blur everywhere could reach.

With `--render-passes N` the bundles are rendered at the evaluation's setting (`infer --scene`,
100 000 photons per pass, N passes, max depth 10) instead of taken from the dataset.

Equal passes, not equal time: a probe of what a filter could gain, not a result. A development
tool (numpy, OpenEXR, pyoidn), never a runtime dependency.

    python3 scripts/postfilter_probe.py --infer target/release/infer --model models/default \
        --dataset data/large --out /tmp/postfilter
"""

import argparse
import glob
import json
import os
import shutil
import subprocess
import sys

import numpy as np

try:
    import Imath
    import OpenEXR
    import pyoidn
except ImportError as e:
    sys.exit(f"postfilter_probe.py: {e}: pip install numpy OpenEXR pyoidn==2.5.1.0")

FLOAT = Imath.PixelType(Imath.PixelType.FLOAT)
# The screen filter's guide tolerances (model/src/screen_filter.rs).
ALBEDO_SIGMA, NORMAL_SIGMA, DEPTH_SIGMA = 0.1, 0.3, 0.05


def scene_probe_arguments(doc, out):
    """The command line the equal-pass probes share: the `infer` binary, the model, the scenes
    (`--dataset DIR --per-family N`: the first N of each family in the *train* split of
    DIR/manifest.json, or `--scenes` directories), their references (a pattern with `{name}`;
    default DIR/references/{name}.exr), the pass count and the output folder (default `out`).
    Resolve them with [`probe_scenes`]."""
    ap = argparse.ArgumentParser(description=doc.split("\n\n")[0])
    ap.add_argument("--infer", default="target/release/infer")
    ap.add_argument("--model", default="models/default")
    ap.add_argument("--dataset", help="a datagen dataset: its train split's scenes")
    ap.add_argument("--per-family", type=int, default=3,
                    help="with --dataset: this many train scenes per family (default 3)")
    ap.add_argument("--scenes", nargs="+", help="scene directories (holding scene.xml)")
    ap.add_argument("--references", help="pattern with {name}")
    ap.add_argument("--passes", type=int, default=64)
    ap.add_argument("--out", default=out)
    return ap


def probe_scenes(a):
    """The scene directories the probe runs on, with `a.references` filled in. Probes choose
    settings, so they run on training scenes only: a scene that a dataset's manifest beside it
    puts in another split is refused (a listing of data/large/scenes holds its test scenes too:
    the first three per family by name once included two of them)."""
    if bool(a.dataset) == bool(a.scenes):
        sys.exit("give either --dataset or --scenes")
    if a.dataset:
        manifest = json.load(open(os.path.join(a.dataset, "manifest.json")))
        taken, scenes = {}, []
        for scene in sorted(manifest["scenes"], key=lambda s: s["id"]):
            if scene["split"] == "train" and taken.get(scene["family"], 0) < a.per_family:
                taken[scene["family"]] = taken.get(scene["family"], 0) + 1
                scenes.append(os.path.join(a.dataset, "scenes", scene["id"]))
        a.references = a.references or os.path.join(a.dataset, "references", "{name}.exr")
    else:
        scenes = a.scenes
    if not a.references:
        sys.exit("--references is needed with --scenes")
    splits = {}  # manifest path → {scene id: split}, each manifest read once
    for scene in scenes:
        root = os.path.dirname(os.path.dirname(os.path.abspath(scene)))
        path = os.path.join(root, "manifest.json")
        if not os.path.exists(path):
            continue
        if path not in splits:
            splits[path] = {s["id"]: s["split"] for s in json.load(open(path))["scenes"]}
        split = splits[path].get(os.path.basename(os.path.normpath(scene)))
        if split not in (None, "train"):
            sys.exit(f"{scene}: in the {split} split of {path}; probes choose on training scenes")
    return scenes


def probe_render(infer, model, scene, passes, out):
    """Renders `scene` (a directory holding `scene.xml`) at the evaluation's setting — 100 000
    photons per pass, `passes`, seed 7, max depth 10 — and reconstructs it with `model`, unless
    done before: returns (output, bundle) paths, `{out}/{name}.exr` and `{out}/{name}_bundle.exr`."""
    name = os.path.basename(os.path.normpath(scene))
    output, bundle = f"{out}/{name}.exr", f"{out}/{name}_bundle.exr"
    if not os.path.exists(bundle):
        subprocess.run(
            [infer, "--model", model, "--scene", f"{scene}/scene.xml", "--passes", str(passes),
             "--photons", "100000", "--seed", "7", "--max-depth", "10", "--output", output],
            check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
        )
    return output, bundle


def read(path, names):
    f = OpenEXR.InputFile(path)
    dw = f.header()["dataWindow"]
    w, h = dw.max.x - dw.min.x + 1, dw.max.y - dw.min.y + 1
    return np.stack(
        [np.frombuffer(f.channel(n, FLOAT), dtype=np.float32).reshape(h, w) for n in names], -1
    )


def rgb(path, prefix=""):
    return read(path, [prefix + "R", prefix + "G", prefix + "B"])


def relmse(x, ref):
    return float(((x - ref) ** 2 / (ref.mean(-1, keepdims=True) ** 2 + 0.01)).mean())


def shifted(a, dy, dx):
    """a moved so that out[y, x] = a[y + dy, x + dx], and where that pixel exists."""
    h, w = a.shape[:2]
    out = np.zeros_like(a)
    inside = np.zeros((h, w), bool)
    dst = (slice(max(0, -dy), min(h, h - dy)), slice(max(0, -dx), min(w, w - dx)))
    src = (slice(max(0, dy), min(h, h + dy)), slice(max(0, dx), min(w, w + dx)))
    out[dst] = a[src]
    inside[dst] = True
    return out, inside


def bilateral(img, var, albedo, normal, depth, sigma, strength, direct=None, noise="sum"):
    """The screen filter's cross-bilateral on `img` (photon part only: `direct` is added back
    unfiltered), range term on `var`, its noise v_c + v_n (`sum`, the screen levels'),
    2·min(v_c, v_n) (`min`, the direct filter's) or 2·v_c (`centre`)."""
    direct = np.zeros_like(img) if direct is None else direct
    photon = img - direct
    r = min(int(np.ceil(2.5 * sigma)), 8)
    inv_depth = 1 / np.maximum(depth, 1e-6)
    weight = np.zeros(img.shape[:2])
    total = np.zeros(img.shape)
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            an, inside = shifted(albedo, dy, dx)
            nn, _ = shifted(normal, dy, dx)
            dn, _ = shifted(depth, dy, dx)
            ln, _ = shifted(img, dy, dx)
            pn, _ = shifted(photon, dy, dx)
            vn, _ = shifted(var, dy, dx)
            e = (dx * dx + dy * dy) / (2 * sigma * sigma)
            e = e + ((an - albedo) ** 2).sum(-1) / (2 * ALBEDO_SIGMA**2)
            e = e + ((nn - normal) ** 2).sum(-1) / (2 * NORMAL_SIGMA**2)
            e = e + ((dn - depth) * inv_depth) ** 2 / (2 * DEPTH_SIGMA**2)
            if strength > 0:
                v = {"sum": vn + var, "min": 2 * np.minimum(vn, var), "centre": 2 * var}[noise]
                excess = np.maximum(((ln - img) ** 2).sum(-1) / 3 - v, 0)
                e = e + excess / np.maximum(strength**2 * v, 1e-30)
            k = np.exp(-e) * inside
            weight += k
            total += k[..., None] * pn
    return total / weight[..., None] + direct


def unfiltered_model(model, out):
    """The model with its `direct_filter` taken out (a copy under `out`): its output holds the
    unfiltered fused photon-free part, so that output less that part is the photon part."""
    with open(f"{model}/model.json") as f:
        config = json.load(f)
    if "direct_filter" not in config:
        return model
    copy = f"{out}/model-without-direct-filter"
    os.makedirs(copy, exist_ok=True)
    for name in os.listdir(model):
        if name.startswith("model.") and name != "model.json":
            shutil.copyfile(f"{model}/{name}", f"{copy}/{name}")
    del config["direct_filter"]
    with open(f"{copy}/model.json", "w") as f:
        json.dump(config, f, indent=2)
    return copy


def fused_direct(bundle):
    """The photon-free parts of eye subpaths A and B weighted by the inverse of their variances
    (as the emission split fuses them) and the fused mean's variance."""
    ya, zb = rgb(bundle, "ydirect."), rgb(bundle, "zdirect.")
    dv = read(bundle, ["directvariance.y", "directvariance.z"])
    va, vb = dv[..., 0], dv[..., 1]
    wa = np.where(va + vb > 0, vb / np.maximum(va + vb, 1e-38), 0.5)[..., None]
    return wa * ya + (1 - wa) * zb, va * vb / np.maximum(va + vb, 1e-38)


def blur(x, sigma):
    """Separable Gaussian blur of an H×W×C image (edges mirrored)."""
    r = int(3 * sigma)
    k = np.exp(-np.arange(-r, r + 1) ** 2 / (2 * sigma * sigma))
    k /= k.sum()
    p = np.pad(x, ((r, r), (r, r), (0, 0)), mode="reflect")
    rows = sum(k[i] * p[i : i + x.shape[0]] for i in range(2 * r + 1))
    return sum(k[i] * rows[:, i : i + x.shape[1]] for i in range(2 * r + 1))


def oracle(candidates, ref, block):
    """Per block×block tile, the candidate image with the least squared relative error."""
    h, w = ref.shape[:2]
    norm = ref.mean(-1, keepdims=True) ** 2 + 0.01
    out = candidates[0].copy()
    for y in range(0, h, block):
        for x in range(0, w, block):
            t = (slice(y, y + block), slice(x, x + block))
            errors = [(((c[t] - ref[t]) ** 2) / norm[t]).sum() for c in candidates]
            out[t] = candidates[int(np.argmin(errors))][t]
    return out


def oidn(color, albedo, normal):
    c = np.ascontiguousarray(np.maximum(color, 0))
    a = np.ascontiguousarray(np.clip(albedo, 0, 1))
    n = np.ascontiguousarray(np.clip(normal, -1, 1))
    return pyoidn.denoise(c, a, n, hdr=True, quality="high")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--infer", default="target/release/infer")
    ap.add_argument("--model", default="models/default")
    ap.add_argument("--dataset", default="data/large", help="dataset with the scenes' bundles")
    ap.add_argument("--heldout", default="scenes/heldout")
    ap.add_argument("--out", default="out/postfilter-probe")
    ap.add_argument("--render-passes", type=int, default=0,
                    help="render each scene's bundle at this pass count instead (100 000 photons)")
    ap.add_argument("--no-oidn", action="store_true", help="skip the OIDN columns")
    a = ap.parse_args()
    os.makedirs(a.out, exist_ok=True)
    scenes = sorted(d for d in os.listdir(a.heldout) if os.path.isdir(os.path.join(a.heldout, d)))
    rows = []
    raw_model = unfiltered_model(a.model, a.out)
    for s in scenes:
        out_path = f"{a.out}/{s}.exr"
        raw_path = f"{a.out}/{s}_without_direct_filter.exr"
        if a.render_passes:
            b = f"{a.out}/{s}_bundle.exr"
            if not os.path.exists(b):
                subprocess.run(
                    [a.infer, "--model", a.model, "--scene", f"{a.heldout}/{s}/scene.xml",
                     "--passes", str(a.render_passes), "--photons", "100000",
                     "--seed", "20261128", "--max-depth", "10", "--output", out_path],
                    check=True, stdout=subprocess.DEVNULL,
                )
        else:
            bundles = sorted(glob.glob(f"{a.dataset}/bundles/{s}/s00_*.exr"))
            if not bundles:
                print(f"skipped {s}: no bundle in {a.dataset}", file=sys.stderr)
                continue
            b = bundles[-1]
        for model, path in ((a.model, out_path), (raw_model, raw_path)):
            subprocess.run(
                [a.infer, "--model", model, "--input", b, "--output", path],
                check=True,
                stdout=subprocess.DEVNULL,
            )
        ref = rgb(f"{a.heldout}/{s}/reference.exr")
        out = rgb(out_path)
        y = rgb(b, "y.")
        levels = [y] + [rgb(b, f"z{j}.") for j in range(1, 5)]
        var = read(b, ["variance.y"] + [f"variance.z{j}" for j in range(1, 5)])
        albedo = rgb(b, "albedo.")
        normal = read(b, ["normal.X", "normal.Y", "normal.Z"])
        depth = read(b, ["depth.Z"])[..., 0]
        # The output's photon-free part: the output less its photon part, which is the output
        # without the direct filter less the unfiltered fused part.
        direct = out - (rgb(raw_path) - fused_direct(b)[0])
        best = min(relmse(x, ref) for x in levels)
        row = {"scene": s, "bundle": os.path.basename(b), "out": relmse(out, ref) / best}
        candidates = [out]
        for sigma in (1.0, 2.0, 3.0):
            for name, v, strength in (
                ("v4r2", var[..., 4], 2.0),
                ("vyr2", var[..., 0], 2.0),
                ("norange", var[..., 4], 0.0),
            ):
                f = bilateral(out, v, albedo, normal, depth, sigma, strength, direct)
                row[f"s{sigma:g}{name}"] = relmse(f, ref) / best
                candidates.append(f)
        for block in (4, 8, 16):
            row[f"oracle{block}"] = relmse(oracle(candidates, ref, block), ref) / best
        if not a.no_oidn:
            row["oidn_out"] = relmse(oidn(out, albedo, normal), ref) / best
        for sigma in (2, 4):
            row[f"low{sigma}"] = relmse(ref + blur(out - ref, sigma), ref) / relmse(out, ref)
        if not a.no_oidn:
            row["oidn_y"] = relmse(oidn(y, albedo, normal), ref) / best
        rows.append(row)
        print(json.dumps({k: round(v, 3) if isinstance(v, float) else v for k, v in row.items()}))
    with open(f"{a.out}/rows.json", "w") as f:
        json.dump(rows, f, indent=1)
    print("\n| variant | median | geometric mean |\n|---|---|---|")
    for k in [k for k in rows[0] if k not in ("scene", "bundle")]:
        x = np.array([r[k] for r in rows])
        print(f"| {k} | {np.median(x):.3f} | {np.exp(np.log(x).mean()):.3f} |")


if __name__ == "__main__":
    main()
