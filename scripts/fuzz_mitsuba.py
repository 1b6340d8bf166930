#!/usr/bin/env python3
"""Differential test of the path tracer against Mitsuba 3 on random scenes.

Where `validate_pt.py` compares hand-written scenes at high sample counts, this script writes
`--count` random scenes from the supported subset (every BSDF plugin with random parameters,
five shape types, area / point / spot / directional / constant lights, random camera and
depth) and renders each small (32x32) with both renderers at the same sample count. A scene is
flagged when the images disagree beyond what noise explains:

    per channel  |mean(ours) - mean(mitsuba)| > max(5 sigma, 1 %) of mean(mitsuba)
    relMSE after 4x4 downsampling > 3 x its noise-only estimate + 1e-5

(sigma and the noise estimate come from the spread of each renderer's independent chunks:
both render the same samples per pixel in 4 runs with different seeds). Flagged scenes are kept under out/fuzz/<seed>/ with both images and a PNG
side by side, to be reduced by hand; the others are deleted unless --keep. Scenes are a
function of (--seed, index), so a flagged one can be regenerated.

Mitsuba is a development tool only (`pip install mitsuba`, variant llvm_ad_rgb).

    python3 scripts/fuzz_mitsuba.py --count 40 --seed 1
    python3 scripts/fuzz_mitsuba.py --count 1 --seed 1 --first 17 --keep   # scene 17 again
    python3 scripts/fuzz_mitsuba.py --count 40 --seed 1 --direct --hide-emitters

`--direct` renders the same scenes with both renderers' `direct` integrator instead (one emitter
sample, as Mitsuba 3.9 weighs delta lights wrongly for more: mitsuba3 issue #1861; 1-3 BSDF
samples). `--hide-emitters` sets the integrator's `hide_emitters` and leaves `mask` out of the
scenes: with it, Mitsuba 3.9.1's `path` drops the light a mask reflects whenever the camera path
then passes through the mask (its `valid_ray` starts false, the quirk described at `material`).
Without --hide-emitters a seed's scenes stay the ones earlier runs saw. `--mesh-lights` draws
area lights only and turns every rectangle and sphere light into an emitting mesh (a cube, an
icosphere or a torus).

`--media` renders with both renderers' `volpath` and fills some spheres and cubes with random
homogeneous media (extinction per channel, albedo, isotropic, Henyey-Greenstein or Rayleigh
phase, light sampling on or off) or heterogeneous ones (random `.vol` grids of extinction and
albedo, written next to the scene) behind null, smooth, rough or thin glass boundaries, and in some scenes puts
the camera and everything else in a thin haze (the filled objects name it as their exterior).

`--extended` draws the scenes from scripts/fuzz_extended.py instead: bitmap textures on every
parameter that takes one, normal and bump maps, anisotropic and Beckmann microfacets, named and
explicit IORs, `<spectrum>` values, OBJ/PLY meshes, instances, `matrix` transforms, an envmap,
thin-lens / orthographic / off-centre cameras and other filters, with the images and meshes each
scene needs written next to it.
"""

import argparse
import json
import re
import random
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from validate_pt import ROOT, downsample, mitsuba, read_exr, side_by_side  # noqa: E402

RES = 32
CHUNKS = 4


def rgb(r, lo=0.1, hi=0.9):
    return ", ".join(f"{r.uniform(lo, hi):.3f}" for _ in range(3))


# Plugins added to `material`'s choice by options (the default list stays, so that a seed's
# scenes stay the same).
EXTRA_MATERIALS = []


def material(r, allow_delta=True, allow_mask=True):
    """A random BSDF element (one of every supported plugin).

    `mask` only where the scene has an environment light: Mitsuba 3.9.1's `path` drops every
    sample whose camera ray passed through a mask and then found no emitter and no non-null
    surface, NEE contributions gathered on the mask included (`valid_ray` in path.cpp), so a
    mask lit by a point light comes out opacity² instead of opacity times as bright. With an
    environment light every ray is valid and the two agree."""
    kinds = ["diffuse", "checker", "roughconductor", "roughplastic", "roughdielectric", "twosided",
             "principled", "blend"]
    if allow_mask:
        kinds.append("mask")
    if allow_delta:
        kinds += ["conductor", "plastic", "dielectric", "thindielectric"]
    kinds += EXTRA_MATERIALS
    k = r.choice(kinds)
    metal = r.choice(["Au", "Cu", "Al", "Ag", "Cr"])
    if k == "diffuse":
        return f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf>'
    if k == "checker":
        return ('<bsdf type="diffuse"><texture type="checkerboard" name="reflectance">'
                f'<rgb name="color0" value="{rgb(r)}"/><rgb name="color1" value="{rgb(r)}"/>'
                f'<transform name="to_uv"><scale value="{r.randint(2, 8)}"/></transform>'
                '</texture></bsdf>')
    if k == "conductor":
        return f'<bsdf type="conductor"><string name="material" value="{metal}"/></bsdf>'
    if k == "roughconductor":
        return ('<bsdf type="roughconductor"><string name="distribution" value="ggx"/>'
                f'<string name="material" value="{metal}"/>'
                f'<float name="alpha" value="{r.uniform(0.05, 0.6):.3f}"/></bsdf>')
    if k == "plastic":
        return ('<bsdf type="plastic">'
                f'<rgb name="diffuse_reflectance" value="{rgb(r)}"/>'
                f'<float name="int_ior" value="{r.uniform(1.3, 1.7):.3f}"/></bsdf>')
    if k == "roughplastic":
        return ('<bsdf type="roughplastic"><string name="distribution" value="ggx"/>'
                f'<rgb name="diffuse_reflectance" value="{rgb(r)}"/>'
                f'<float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>')
    if k == "dielectric":
        return f'<bsdf type="dielectric"><float name="int_ior" value="{r.uniform(1.3, 1.8):.3f}"/></bsdf>'
    if k == "thindielectric":
        return f'<bsdf type="thindielectric"><float name="int_ior" value="{r.uniform(1.3, 1.7):.3f}"/></bsdf>'
    if k == "roughdielectric":
        return ('<bsdf type="roughdielectric"><string name="distribution" value="ggx"/>'
                f'<float name="int_ior" value="{r.uniform(1.3, 1.7):.3f}"/>'
                f'<float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>')
    if k == "twosided":
        return f'<bsdf type="twosided"><bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf></bsdf>'
    if k == "principled":
        params = [f'<rgb name="base_color" value="{rgb(r)}"/>']
        for name, lo, hi in [("roughness", 0.15, 0.9), ("metallic", 0, 1), ("specular", 0.2, 0.8),
                             ("spec_tint", 0, 1), ("sheen", 0, 1), ("clearcoat", 0, 1),
                             ("clearcoat_gloss", 0, 1), ("anisotropic", 0, 0.8)]:
            if r.random() < 0.6:
                params.append(f'<float name="{name}" value="{r.uniform(lo, hi):.3f}"/>')
        return f'<bsdf type="principled">{"".join(params)}</bsdf>'
    if k == "principledthin":
        params = [f'<rgb name="base_color" value="{rgb(r)}"/>']
        for name, lo, hi in [("roughness", 0.15, 0.9), ("spec_trans", 0, 1), ("eta", 1.1, 1.9),
                             ("spec_tint", 0, 1), ("sheen", 0, 1), ("sheen_tint", 0, 1),
                             ("flatness", 0, 1), ("diff_trans", 0, 2), ("anisotropic", 0, 0.8)]:
            if r.random() < 0.6:
                params.append(f'<float name="{name}" value="{r.uniform(lo, hi):.3f}"/>')
        return f'<bsdf type="principledthin">{"".join(params)}</bsdf>'
    if k == "blend":
        # Two non-delta, non-transmitting models. Mitsuba 3.9.1's blendbsdf loses energy with
        # delta models, and gains some when one model transmits: where the other model's sample
        # fails, it evaluates the transmitting one in the failed sample's direction (a
        # roughconductor + roughdielectric blend seen from inside has albedo 1.95 in Mitsuba,
        # the blend of its models' albedos is 1.26; docs/validation.md).
        a, b = material(r, False, False), material(r, False, False)
        if any(t in a + b for t in ("blendbsdf", "roughdielectric", "principledthin")):
            a = f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf>'
        if "roughdielectric" in b or "principledthin" in b:
            b = f'<bsdf type="roughplastic"><string name="distribution" value="ggx"/><float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>'
        return f'<bsdf type="blendbsdf"><float name="weight" value="{r.uniform(0.2, 0.8):.3f}"/>{a}{b}</bsdf>'
    # mask
    return (f'<bsdf type="mask"><float name="opacity" value="{r.uniform(0.3, 0.9):.3f}"/>'
            f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf></bsdf>')


def shape(r, bsdf):
    """A random object standing on or above the floor (y = 0), with `bsdf` nested. Nothing
    shares a plane with the floor (a cube's bottom face there makes the closest hit a tie that
    the two renderers break differently)."""
    x, z = r.uniform(-1.2, 1.2), r.uniform(-1.2, 1.2)
    k = r.choice(["sphere", "cube", "cylinder", "disk", "rectangle"])
    if k == "sphere":
        rad = r.uniform(0.25, 0.6)
        return (f'<shape type="sphere"><point name="center" x="{x:.3f}" y="{rad:.3f}" z="{z:.3f}"/>'
                f'<float name="radius" value="{rad:.3f}"/>{bsdf}</shape>')
    if k == "cylinder":
        h, rad = r.uniform(0.3, 1.2), r.uniform(0.1, 0.4)
        return (f'<shape type="cylinder"><point name="p0" x="{x:.3f}" y="0" z="{z:.3f}"/>'
                f'<point name="p1" x="{x:.3f}" y="{h:.3f}" z="{z:.3f}"/>'
                f'<float name="radius" value="{rad:.3f}"/>{bsdf}</shape>')
    s = r.uniform(0.2, 0.5)
    if k == "cube":
        return (f'<shape type="cube"><transform name="to_world"><scale value="{s:.3f}"/>'
                f'<rotate y="1" angle="{r.uniform(0, 90):.1f}"/><translate x="{x:.3f}" y="{s + 0.02:.3f}" z="{z:.3f}"/>'
                f'</transform>{bsdf}</shape>')
    # disk / rectangle: tilted towards the camera side, floating
    return (f'<shape type="{k}"><transform name="to_world"><scale value="{s:.3f}"/>'
            f'<rotate x="1" angle="{r.uniform(-80, 10):.1f}"/><rotate y="1" angle="{r.uniform(-60, 60):.1f}"/>'
            f'<translate x="{x:.3f}" y="{r.uniform(0.3, 1.0):.3f}" z="{z:.3f}"/></transform>{bsdf}</shape>')


def area_rectangle(r, radiance):
    """A downward-facing rectangular area light above the scene; `radiance()` gives its
    radiance element (called after the placement is drawn)."""
    s = r.uniform(0.3, 1.0)
    place = (f'<transform name="to_world"><scale value="{s:.3f}"/><rotate x="1" angle="90"/>'
             f'<translate x="{r.uniform(-1, 1):.3f}" y="{r.uniform(2.5, 3.5):.3f}" '
             f'z="{r.uniform(-1, 1):.3f}"/></transform>')
    return f'<shape type="rectangle">{place}<emitter type="area">{radiance()}</emitter></shape>'


def spot_light(r, turn=False, slide=lambda: ""):
    """A spot aimed at the origin from above; with `turn` rotated about its beam first, `slide()`
    an extra element (a projected texture, drawn last)."""
    spin = f'<rotate z="1" angle="{r.uniform(0, 360):.1f}"/>' if turn else ""
    return (f'<emitter type="spot"><transform name="to_world">{spin}<lookat origin="{r.uniform(-2, 2):.3f}, '
            f'{r.uniform(2, 3.5):.3f}, {r.uniform(-2, 2):.3f}" target="0, 0, 0"/></transform>'
            f'<rgb name="intensity" value="{rgb(r, 5, 30)}"/>'
            f'<float name="cutoff_angle" value="{r.uniform(20, 45):.1f}"/>'
            f'<float name="beam_width" value="{r.uniform(10, 19):.1f}"/>{slide()}</emitter>')


def light(r, allow_environment=True, area_only=False):
    """A random light; with `area_only` an area light or a constant sky (no delta lights)."""
    kinds = ["area", "area-sphere"] if area_only else ["area", "area-sphere", "point", "spot", "directional"]
    k = r.choice(kinds + ["constant"] if allow_environment else kinds)
    if k == "area":
        return area_rectangle(r, lambda: f'<rgb name="radiance" value="{rgb(r, 3, 12)}"/>')
    if k == "area-sphere":
        return (f'<shape type="sphere"><point name="center" x="{r.uniform(-1.5, 1.5):.3f}" '
                f'y="{r.uniform(1.5, 3):.3f}" z="{r.uniform(-1.5, 1.5):.3f}"/>'
                f'<float name="radius" value="{r.uniform(0.1, 0.3):.3f}"/>'
                f'<emitter type="area"><rgb name="radiance" value="{rgb(r, 5, 20)}"/></emitter></shape>')
    if k == "point":
        return (f'<emitter type="point"><point name="position" x="{r.uniform(-1.5, 1.5):.3f}" '
                f'y="{r.uniform(1.5, 3):.3f}" z="{r.uniform(-1.5, 1.5):.3f}"/>'
                f'<rgb name="intensity" value="{rgb(r, 3, 15)}"/></emitter>')
    if k == "spot":
        return spot_light(r)
    if k == "directional":
        return (f'<emitter type="directional"><vector name="direction" x="{r.uniform(-1, 1):.3f}" y="-1" '
                f'z="{r.uniform(-1, 1):.3f}"/><rgb name="irradiance" value="{rgb(r, 0.5, 3)}"/></emitter>')
    return f'<emitter type="constant"><rgb name="radiance" value="{rgb(r, 0.1, 1)}"/></emitter>'


def scene_xml(seed, index, lights="all", delta_materials=True, masks=True):
    """Scene `index` of generator seed `seed`; `lights="area"`: area lights and a sky only;
    without `delta_materials` no smooth (delta) BSDF, so that every light path is one a path
    tracer can find; without `masks` no `mask` BSDF."""
    r = random.Random(seed * 1_000_003 + index)
    area_only = lights == "area"
    elev, azim, dist = r.uniform(10, 55), r.uniform(0, 360), r.uniform(3.5, 6)
    e, a = np.radians(elev), np.radians(azim)
    origin = (dist * np.cos(e) * np.sin(a), dist * np.sin(e), dist * np.cos(e) * np.cos(a))
    # Mitsuba allows one environment emitter per scene.
    first = light(r, True, area_only)
    lights = [first] + [light(r, "constant" not in first, area_only) for _ in range(r.randint(0, 1))]
    environment = any("constant" in l for l in lights) and masks
    lights = "\n    ".join(lights)
    floor = material(r, allow_delta=False, allow_mask=environment)
    objects = "\n    ".join(shape(r, material(r, delta_materials, environment))
                             for _ in range(r.randint(1, 3)))
    return f"""<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="res" value="{RES}"/>
    <integrator type="path"><integer name="max_depth" value="{r.randint(2, 8)}"/></integrator>
    <sensor type="perspective">
        <float name="fov" value="{r.uniform(30, 60):.1f}"/>
        <transform name="to_world"><lookat origin="{origin[0]:.3f}, {origin[1]:.3f}, {origin[2]:.3f}" target="0, 0.3, 0" up="0, 1, 0"/></transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="$res"/><rfilter type="box"/></film>
    </sensor>
    <shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/></transform>{floor}</shape>
    {objects}
    {lights}
</scene>
"""


def integrator_variant(xml_text, seed, index, direct, hide):
    """The scene's `<integrator>` replaced for --direct / --hide-emitters, and the Mitsuba
    integrator dict that matches it. The BSDF sample count comes from its own random stream."""
    max_depth = int(xml_text.split('name="max_depth" value="')[1].split('"')[0])
    old = f'<integrator type="path"><integer name="max_depth" value="{max_depth}"/></integrator>'
    hide_xml = '<boolean name="hide_emitters" value="true"/>' if hide else ""
    if direct:
        bsdf_samples = random.Random(seed * 7_919 + index).randint(1, 3)
        new = (f'<integrator type="direct"><integer name="emitter_samples" value="1"/>'
               f'<integer name="bsdf_samples" value="{bsdf_samples}"/>{hide_xml}</integrator>')
        params = {"type": "direct", "emitter_samples": 1, "bsdf_samples": bsdf_samples, "hide_emitters": hide}
    else:
        new = f'<integrator type="path"><integer name="max_depth" value="{max_depth}"/>{hide_xml}</integrator>'
        params = {"type": "path", "max_depth": max_depth, "hide_emitters": hide}
    return xml_text.replace(old, new), params


def render_mitsuba(xml, spp, params):
    """Mitsuba's image of `xml` with the integrator `params` (a `mi.load_dict` dict), in CHUNKS
    runs of spp/CHUNKS samples: (mean, stacked chunks)."""
    mi = mitsuba()
    mi.set_variant("llvm_ad_rgb")
    sc = mi.load_file(str(xml), spp=spp // CHUNKS, res=RES)
    integrator = mi.load_dict(params)
    chunks = [np.array(mi.render(sc, integrator=integrator, spp=spp // CHUNKS, seed=7000 + k),
                       dtype=np.float64)[..., :3] for k in range(CHUNKS)]
    return np.mean(chunks, axis=0), np.stack(chunks)


def fuzz_arguments(description, spp, spp_help, out_name):
    """The command line both fuzz scripts share (scene range, seed, spp, binary, output)."""
    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--count", type=int, default=20, help="scenes to try")
    ap.add_argument("--first", type=int, default=0, help="index of the first scene")
    ap.add_argument("--seed", type=int, default=1, help="scene generator seed")
    ap.add_argument("--spp", type=int, default=spp, help=spp_help)
    ap.add_argument("--bin", default=str(ROOT / "target" / "release" / "render"), help="our render binary")
    ap.add_argument("--out", default=str(ROOT / "out" / out_name), help="output folder")
    ap.add_argument("--keep", action="store_true", help="keep the files of scenes that agree")
    return ap


def run_render(cmd):
    """Runs our `render` with `cmd`; RuntimeError with the end of its stderr when it fails."""
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    if done.returncode != 0:
        raise RuntimeError(done.stderr.strip()[-400:])


def render_path_chunks(binary, xml, spp, out_dir, prefix, *extra, integrator="path"):
    """Our path tracer (or `integrator`) on `xml` in CHUNKS runs of spp/CHUNKS samples (seeds
    1..CHUNKS, images `<prefix>_<k>.exr` in `out_dir`), stacked: their spread is our noise."""
    chunks = []
    for k in range(CHUNKS):
        exr = out_dir / f"{prefix}_{k}.exr"
        run_render([binary, xml, "--integrator", integrator, *extra, "--spp", spp // CHUNKS,
                    "--seed", k + 1, "--out", exr])
        chunks.append(read_exr(exr))
    return np.stack(chunks)


def scene_dirs(args):
    """(index, folder, scene.xml path) of each scene to try: `<out>/<seed>/<index>/`, created."""
    out = Path(args.out) / str(args.seed)
    for index in range(args.first, args.first + args.count):
        d = out / f"{index:04d}"
        d.mkdir(parents=True, exist_ok=True)
        yield index, d, d / "scene.xml"


def finish(out, rows, flagged, count):
    """Writes `summary.json`, prints the verdict and exits (1 when a scene is flagged)."""
    (out / "summary.json").write_text(json.dumps(rows, indent=1) + "\n")
    print(f"{len(flagged)} of {count} scenes flagged: {flagged} (files under {out})")
    sys.exit(1 if flagged else 0)


def restyled(text, folder):
    """The same scene in Mitsuba's other spellings: the sensor's sampler and the film's rfilter
    declared at the top level and named by a <ref>, every <rgb> value as an unbounded
    <spectrum type="srgb"> (every second one declared at the top level and named by a <ref>),
    and the scene's own files (textures, meshes) moved into an `assets` subfolder that a
    <path> names."""
    top = []
    for tag, ident in (("sampler", "fuzz_sampler"), ("rfilter", "fuzz_rfilter")):
        m = re.search(rf'<{tag}\b[^>]*?(/>|>.*?</{tag}>)', text, re.S)
        if m:
            element = m.group(0)
            top.append(element.replace(f"<{tag} ", f'<{tag} id="{ident}" ', 1))
            text = text.replace(element, f'<ref id="{ident}"/>', 1)
    # Every second colour is declared at the top level as a typed spectrum (Mitsuba's spectra
    # are textures) and named by a <ref> where it was; the others become inline spectra.
    declared = []

    def colour(m):
        name, value = m.group(1), m.group(2)
        spectrum = (f'<rgb name="color" value="{value}"/>'
                    '<boolean name="unbounded" value="true"/></spectrum>')
        colour.count += 1
        if colour.count % 2 == 0:
            ident = f"fuzz_colour{len(declared)}"
            declared.append(f'<spectrum type="srgb" id="{ident}">{spectrum}')
            return f'<ref name="{name}" id="{ident}"/>'
        return f'<spectrum type="srgb" name="{name}">{spectrum}'
    colour.count = 0
    text = re.sub(r'<rgb name="([A-Za-z0-9_]+)" value="([^"]*)"/>', colour, text)
    top += declared
    assets = [f for f in folder.iterdir() if f.is_file() and f.suffix != ".xml"]
    if assets:
        (folder / "assets").mkdir(exist_ok=True)
        for f in assets:
            f.rename(folder / "assets" / f.name)
        top.insert(0, '<path value="assets"/>')
    # After the <default>s: a `$name` is substituted only once its default has been read.
    anchor = list(re.finditer(r"<default [^>]*/>", text)) or [re.search(r"<scene[^>]*>", text)]
    at = anchor[-1].end()
    return text[:at] + "\n    " + "\n    ".join(top) + text[at:]


def torus_mesh(rings, sides, small):
    """A torus about +y (ring radius 1, tube radius `small`): positions, outward normals, uvs
    and counter-clockwise (outward) quads."""
    pos, nrm, uv, quads = [], [], [], []
    for i in range(rings):
        a = 2 * np.pi * i / rings
        for j in range(sides):
            b = 2 * np.pi * j / sides
            rr = 1 + small * np.cos(b)
            pos.append((rr * np.cos(a), small * np.sin(b), rr * np.sin(a)))
            nrm.append((np.cos(b) * np.cos(a), np.sin(b), np.cos(b) * np.sin(a)))
            uv.append((i / rings, j / sides))
    at = lambda i, j: (i % rings) * sides + (j % sides)  # noqa: E731
    for i in range(rings):
        for j in range(sides):
            quads.append((at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)))
    return pos, nrm, uv, quads


def mesh_lights(text, folder, seed, index):
    """The scene with each rectangular and spherical area light (the generators'
    `area_rectangle` and area spheres) turned into an emitting mesh in the same place: a `cube`, an icosphere or a
    torus written as OBJ next to the scene (vertex normals or not, tilted) — for NEE's choice
    of a mesh light's triangle by importance."""
    from make_scene_assets import icosphere, write_obj

    r = random.Random(seed * 1_000_037 + index + 29)
    count = [0]

    def mesh(m):
        transform, emitter = m.group(1), m.group(2)
        if "<texture" in emitter:
            # Mitsuba samples a textured radiance through the texture's uv distribution and
            # finds the point of a uv on the shape; on a mesh whose uvs cover it more than once
            # (a cube's six faces, a torus's or sphere's seam) its NEE misses or double-counts
            # parts (a textured `cube` emitter: 0 by NEE, 1.43e-3 by BSDF sampling, ours 1.40e-3
            # and 1.41e-3). Such lights stay rectangles.
            return m.group(0)
        kind = r.choice(["cube", "icosphere", "torus"])
        # No `flip_normals`: a closed mesh emitting inwards lights the scene only through leaks
        # (both renderers, a few 1e-4 of brightness that differ by 2x; docs/validation.md).
        flip = ""
        tilt = (f'<rotate x="1" angle="{r.uniform(-60, 60):.1f}"/>'
                f'<rotate z="1" angle="{r.uniform(-60, 60):.1f}"/>')
        # The tilt goes first: the rectangle's own transform still places and sizes it.
        transform = transform.replace('<transform name="to_world">', f'<transform name="to_world">{tilt}', 1)
        if kind == "cube":  # half the rectangle's size: a cube spans [-1, 1]³
            transform = re.sub(r'<scale value="([0-9.]+)"/>', lambda v: f'<scale value="{0.5 * float(v.group(1)):.3f}"/>',
                               transform, count=1)
            return f'<shape type="cube">{flip}{transform}<emitter type="area">{emitter}</emitter></shape>'
        count[0] += 1
        name = f"light{count[0]}.obj"
        normals = r.random() < 0.5
        if kind == "icosphere":
            pos, tris = icosphere(r.randint(1, 3))
            uv = [(0.5 + np.arctan2(p[0], p[2]) / (2 * np.pi), np.arccos(max(-1, min(1, p[1]))) / np.pi) for p in pos]
            write_obj(folder / name, [tuple(0.5 * c for c in p) for p in pos], pos if normals else None, uv, tris,
                      "fuzz emitting icosphere")
        else:
            # Thick tubes: on thin ones light sampling and BSDF sampling disagree by a few %
            # in both renderers (docs/validation.md).
            pos, nrm, uv, quads = torus_mesh(r.randint(8, 32), r.randint(4, 12), r.uniform(0.25, 0.45))
            write_obj(folder / name, [tuple(0.6 * c for c in p) for p in pos], nrm if normals else None, uv, quads,
                      "fuzz emitting torus")
        return (f'<shape type="obj"><string name="filename" value="{name}"/>{flip}{transform}'
                f'<emitter type="area">{emitter}</emitter></shape>')

    # (?:(?!</x>).)* stays inside one element: a non-light rectangle must not match up to the
    # next shape's emitter.
    text = re.sub(r'<shape type="rectangle">(<transform name="to_world">(?:(?!</transform>).)*</transform>)'
                  r'<emitter type="area">((?:(?!</emitter>).)*)</emitter></shape>', mesh, text, flags=re.S)

    def sphere(m):
        x, y, z, radius, emitter = m.groups()
        # Twice the radius: the meshes above are half a unit across.
        place = (f'<transform name="to_world"><scale value="{2 * float(radius):.3f}"/>'
                 f'<translate x="{x}" y="{y}" z="{z}"/></transform>')
        return mesh(re.match(r"(.*)\x00(.*)", f"{place}\x00{emitter}", re.S))

    return re.sub(r'<shape type="sphere"><point name="center" x="([-0-9.]+)" y="([-0-9.]+)" z="([-0-9.]+)"/>'
                  r'<float name="radius" value="([0-9.]+)"/><emitter type="area">((?:(?!</emitter>).)*)</emitter></shape>',
                  sphere, text, flags=re.S)


def random_medium(r, attrs, thin=False):
    """A random `homogeneous` medium element with attributes `attrs` (id or name); `thin`: a
    haze (a few percent extinction per unit)."""
    m = ET.Element("medium", {"type": "homogeneous", **attrs})
    # Mitsuba reads an rgb sigma_t as a reflectance (at most 1): `scale` sets the density.
    if r.random() < 0.6:
        ET.SubElement(m, "rgb", name="sigma_t", value=", ".join(f"{r.uniform(0.2, 1.0):.3f}" for _ in range(3)))
    else:
        ET.SubElement(m, "float", name="sigma_t", value=f"{r.uniform(0.2, 1.0):.3f}")
    scale = r.uniform(0.03, 0.25) if thin else r.uniform(0.5, 6.0)
    ET.SubElement(m, "float", name="scale", value=f"{scale:.3f}")
    if r.random() < 0.6:
        ET.SubElement(m, "rgb", name="albedo", value=", ".join(f"{r.uniform(0.3, 1.0):.3f}" for _ in range(3)))
    else:
        ET.SubElement(m, "float", name="albedo", value=f"{r.uniform(0.3, 1.0):.3f}")
    if r.random() < 0.6:
        phase = ET.SubElement(m, "phase", type="hg")
        ET.SubElement(phase, "float", name="g", value=f"{r.uniform(-0.7, 0.85):.3f}")
    elif r.random() < 0.5:
        ET.SubElement(m, "phase", type="isotropic")
    if r.random() < 0.2:
        ET.SubElement(m, "boolean", name="sample_emitters", value="false")
    return m


def write_vol(path, data):
    """Writes `data` (z, y, x, channels) as a Mitsuba .vol grid over the unit cube."""
    z, y, x, c = data.shape
    header = b"VOL" + bytes([3]) + np.array([1, x, y, z, c], dtype="<i4").tobytes()
    box = np.array([0, 0, 0, 1, 1, 1], dtype="<f4").tobytes()
    path.write_bytes(header + box + np.ascontiguousarray(data, dtype="<f4").tobytes())


def object_box(shape):
    """Centre and half-size of a generated sphere or cube (from its XML)."""
    if shape.get("type") == "sphere":
        c = shape.find("point[@name='center']")
        centre = np.array([float(c.get(k)) for k in "xyz"])
        return centre, float(shape.find("float[@name='radius']").get("value"))
    transform = shape.find("transform[@name='to_world']")
    t = transform.find("translate")
    centre = np.array([float(t.get(k, 0)) for k in "xyz"])
    return centre, float(transform.find("scale").get("value")) * 1.5


def grid_medium(r, shape, folder, k):
    """A random `heterogeneous` medium for `shape`: a `gridvolume` sigma_t (2-6 cells per axis,
    1 or 3 channels, random filter and wrap mode) over a box around the object, written to
    `folder`/grid<k>.vol, and a constant or grid albedo."""
    m = ET.Element("medium", {"type": "heterogeneous", "name": "interior"})
    centre, half = object_box(shape)
    half *= r.uniform(0.7, 1.3)
    lo = centre - half
    to_world = (f'<transform name="to_world"><scale value="{2 * half:.4f}"/>'
                f'<translate x="{lo[0]:.4f}" y="{lo[1]:.4f}" z="{lo[2]:.4f}"/></transform>')

    def volume(name, channels, lo_value, hi_value):
        res = [r.randint(2, 6) for _ in range(3)]
        data = np.array([r.uniform(lo_value, hi_value) for _ in range(int(np.prod(res)) * channels)])
        write_vol(folder / f"grid{k}_{name}.vol", data.reshape(res[2], res[1], res[0], channels))
        v = ET.fromstring(f'<volume type="gridvolume" name="{name}">'
                          f'<string name="filename" value="grid{k}_{name}.vol"/>{to_world}</volume>')
        ET.SubElement(v, "string", name="filter_type", value=r.choice(["trilinear", "nearest"]))
        ET.SubElement(v, "string", name="wrap_mode", value=r.choice(["clamp", "repeat", "mirror"]))
        return v

    m.append(volume("sigma_t", r.choice([1, 3]), 0.0, 1.0))
    ET.SubElement(m, "float", name="scale", value=f"{r.uniform(0.5, 6.0):.3f}")
    if r.random() < 0.5:
        m.append(volume("albedo", r.choice([1, 3]), 0.3, 1.0))
    else:
        ET.SubElement(m, "float", name="albedo", value=f"{r.uniform(0.3, 1.0):.3f}")
    if r.random() < 0.5:
        phase = ET.SubElement(m, "phase", type="hg")
        ET.SubElement(phase, "float", name="g", value=f"{r.uniform(-0.7, 0.85):.3f}")
    return m


def random_phase(r, depth=0):
    """A random phase function element: `hg`, `rayleigh`, `isotropic`, `tabphase` (4-12 values,
    some zero) or, above depth 1 only as leaves, `blendphase` (a float or constvolume weight)."""
    kind = r.choice(["hg", "rayleigh", "isotropic", "tabphase", "tabphase"] + (["blendphase"] * 2 if depth < 2 else []))
    phase = ET.Element("phase", type=kind)
    if kind == "hg":
        ET.SubElement(phase, "float", name="g", value=f"{r.uniform(-0.8, 0.9):.3f}")
    elif kind == "tabphase":
        values = [0.0 if r.random() < 0.15 else r.uniform(0.0, 3.0) for _ in range(r.randint(4, 12))]
        values[r.randrange(len(values))] = r.uniform(0.5, 3.0)
        ET.SubElement(phase, "string", name="values", value=", ".join(f"{v:.3f}" for v in values))
    elif kind == "blendphase":
        if r.random() < 0.7:
            ET.SubElement(phase, "float", name="weight", value=f"{r.uniform(0.0, 1.0):.3f}")
        else:
            v = ET.SubElement(phase, "volume", type="constvolume", name="weight")
            ET.SubElement(v, "rgb", name="value", value=", ".join(f"{r.uniform(0.0, 1.0):.3f}" for _ in range(3)))
        phase.append(random_phase(r, depth + 1))
        phase.append(random_phase(r, depth + 1))
    return phase


def with_media(text, seed, index, folder, more_phases=False):
    """--media: the scene rendered by `volpath`, some of its spheres and cubes filled with a
    random medium (homogeneous, or heterogeneous from random grids written to `folder`) behind
    a null, glass, rough glass or thin glass boundary, and in some scenes a haze around
    everything (the sensor's medium and the filled objects' exterior). `more_phases`
    (--phases): every medium's phase function drawn by `random_phase` instead."""
    r = random.Random(seed * 4_999_999 + index)
    # Later additions draw from streams of their own, so that a seed's earlier scenes stay.
    grids = random.Random(seed * 7_777_777 + index)
    phases = random.Random(seed * 3_333_331 + index)
    tables = random.Random(seed * 5_555_557 + index)
    root = ET.fromstring(text)
    integrator = root.find("integrator")
    integrator.set("type", "volpath")
    hide = integrator.find("boolean[@name='hide_emitters']")
    params = {"type": "volpath", "max_depth": int(integrator.find("integer[@name='max_depth']").get("value")),
              "hide_emitters": hide is not None and hide.get("value") == "true"}
    # No haze around an environment light: in both renderers only light sampling reaches an
    # infinite light through an open medium (at twice the scene's radius), but Mitsuba weighs
    # those samples by MIS against BSDF samples that cannot get there and loses that share of
    # the sky's light: a known difference (docs/validation.md). A sun (a delta light) renders
    # the same in both.
    environment = any(root.find(f"emitter[@type='{t}']") is not None for t in ("constant", "envmap"))
    haze = r.random() < 0.4 and not environment
    if haze:
        haze_medium = random_medium(r, {"id": "haze"}, thin=True)
        if more_phases:
            for old in haze_medium.findall("phase"):
                haze_medium.remove(old)
            haze_medium.append(random_phase(tables))
        root.insert(list(root).index(root.find("sensor")), haze_medium)
        ET.SubElement(root.find("sensor"), "ref", id="haze")
    filled = 0
    for shape in root.findall("shape"):
        if shape.get("type") not in ("sphere", "cube") or shape.find("emitter") is not None:
            continue
        if filled and r.random() < 0.3:
            continue
        filled += 1
        for old in shape.findall("bsdf") + shape.findall("ref"):
            shape.remove(old)
        kind = r.choice(["null", "dielectric", "thindielectric", "roughdielectric"])
        bsdf = ET.SubElement(shape, "bsdf", type=kind)
        if kind != "null":
            ET.SubElement(bsdf, "float", name="int_ior", value=f"{r.uniform(1.2, 1.6):.3f}")
        if kind == "roughdielectric":
            ET.SubElement(bsdf, "float", name="alpha", value=f"{r.uniform(0.05, 0.4):.3f}")
        if grids.random() < 0.5:
            medium = grid_medium(grids, shape, folder, filled)
        else:
            medium = random_medium(r, {"name": "interior"})
        # Half of the media without a Henyey-Greenstein phase get Rayleigh's.
        if medium.find("phase[@type='hg']") is None and phases.random() < 0.5:
            for old in medium.findall("phase"):
                medium.remove(old)
            ET.SubElement(medium, "phase", type="rayleigh")
        if more_phases:
            for old in medium.findall("phase"):
                medium.remove(old)
            medium.append(random_phase(tables))
        shape.append(medium)
        if haze:
            ET.SubElement(shape, "ref", name="exterior", id="haze")
    return ET.tostring(root, encoding="unicode"), params


def legacy_names(text):
    """The scene as a Mitsuba 0.6 file: version 0.6.0 and every parameter name in camelCase
    (`int_ior` -> `intIor`), which Mitsuba 3 turns back (`camel_to_underscore_case`);
    `<default>` names are `$` parameters and stay."""
    def camel(m):
        head, name = m.group(1), m.group(2)
        parts = name.split("_")
        return head + parts[0] + "".join(p[:1].upper() + p[1:] for p in parts[1:]) + '"'
    text = re.sub(r'(<(?!default\b)[a-z]+\b[^>]*?\sname=")([A-Za-z0-9_]+)"', camel, text)
    return text.replace('<scene version="3.0.0">', '<scene version="0.6.0">', 1)


def main():
    ap = fuzz_arguments(__doc__.split("\n")[0], 1024, "samples per pixel, both renderers", "fuzz")
    ap.add_argument("--direct", action="store_true", help="compare the `direct` integrators instead of `path`")
    ap.add_argument("--hide-emitters", action="store_true", help="set the integrator's hide_emitters")
    ap.add_argument("--extended", action="store_true",
                    help="scenes with textures, normal/bump maps, meshes, instances, envmaps, other "
                         "cameras and filters (scripts/fuzz_extended.py)")
    ap.add_argument("--restyle", action="store_true",
                    help="write each scene in Mitsuba's other spellings: the sampler and rfilter at "
                         "the top level named by <ref>, colours as <spectrum type=\"srgb\">, the "
                         "scene's files in a subfolder found through <path>")
    ap.add_argument("--mesh-lights", action="store_true",
                    help="turn each rectangular area light into an emitting mesh (cube, icosphere or "
                         "torus OBJ, tilted, normals or not): NEE's triangle choice by importance")
    ap.add_argument("--media", action="store_true",
                    help="render with `volpath`, some objects filled with random homogeneous media, "
                         "sometimes everything in a haze")
    ap.add_argument("--phases", action="store_true",
                    help="with --media: random phase functions, tabulated and blended ones included")
    ap.add_argument("--thin", action="store_true",
                    help="the thin principled BSDF (principledthin) among the random materials, "
                         "three times as likely as any other")
    ap.add_argument("--legacy", action="store_true",
                    help="write each scene as a Mitsuba 0.6 file (version 0.6.0, camelCase parameter "
                         "names), which both renderers must upgrade alike")
    args = ap.parse_args()
    if args.thin:
        EXTRA_MATERIALS.extend(["principledthin"] * 3)
    if args.media and (args.direct or args.legacy):
        sys.exit("--media renders with volpath: not with --direct or --legacy")
    out = Path(args.out) / str(args.seed)
    out.mkdir(parents=True, exist_ok=True)
    flagged, rows = [], []
    for index, d, xml in scene_dirs(args):
        # With --mesh-lights area lights only (rectangles and spheres, which become meshes).
        lights = "area" if args.mesh_lights else "all"
        if args.extended:
            from fuzz_extended import extended_scene_xml
            text = extended_scene_xml(args.seed, index, d, masks=not args.hide_emitters, lights=lights)
        else:
            text = scene_xml(args.seed, index, masks=not args.hide_emitters, lights=lights)
        text, params = integrator_variant(text, args.seed, index, args.direct, args.hide_emitters)
        if args.mesh_lights:
            text = mesh_lights(text, d, args.seed, index)
        if args.media:
            text, params = with_media(text, args.seed, index, d, args.phases)
        if args.legacy:
            text = legacy_names(text)
        if args.restyle:
            text = restyled(text, d)
        xml.write_text(text)
        try:
            ref, ref_chunks = render_mitsuba(xml, args.spp, params)
        except RuntimeError as e:  # a generator mistake, not a finding about our renderer
            sys.exit(f"{index:4d}: Mitsuba refused the scene {xml}: {e}")
        # Ours in as many independent chunks, so that the noise estimate sees each renderer's
        # own variance (their sampling strategies differ).
        try:
            ours_chunks = render_path_chunks(args.bin, xml, args.spp, d, "ours",
                                             integrator="direct" if args.direct else
                                             "volpath" if args.media else "path")
        except RuntimeError as e:
            flagged.append(index)
            rows.append({"index": index, "error": str(e)})
            print(f"{index:4d}: ours failed: {str(e)[-200:]}", flush=True)
            continue
        ours = ours_chunks.mean(axis=0)
        a, b = downsample(ours), downsample(ref)
        denom = b * b + 1e-2
        rel_mse = float(np.mean((a - b) ** 2 / denom))
        var = lambda c: np.stack([downsample(x) for x in c]).var(axis=0, ddof=1) / CHUNKS
        noise_ref, noise_ours = (float(np.mean(var(c) / denom)) for c in (ref_chunks, ours_chunks))
        noise = noise_ref + noise_ours
        mean_a, mean_b = ours.mean(axis=(0, 1)), ref.mean(axis=(0, 1))
        mean_rel = (mean_a - mean_b) / np.maximum(mean_b, 1e-8)
        # sigma of the difference of the two image means, from both renderers' chunk spread.
        sigma = np.sqrt((ref_chunks.mean(axis=(1, 2)).var(axis=0, ddof=1)
                         + ours_chunks.mean(axis=(1, 2)).var(axis=0, ddof=1)) / CHUNKS)
        tol = np.maximum(5 * sigma, 0.01 * np.abs(mean_b))
        bad_mean = bool(np.any(np.abs(mean_a - mean_b) > tol))
        bad_mse = rel_mse > 3 * noise + 1e-5
        # Our noise over Mitsuba's at the same spp: not a flag (sampling strategies differ),
        # but where it is large, ours wastes samples (the NEE light selection was found so).
        row = {"index": index, "rel_mse": rel_mse, "noise": noise,
               "noise_ratio": noise_ours / max(noise_ref, 1e-30), "mean_ours": mean_a.tolist(),
               "mean_mitsuba": mean_b.tolist(), "mean_rel": mean_rel.tolist(),
               "flag": bad_mean or bad_mse}
        rows.append(row)
        verdict = "FLAG" if row["flag"] else "ok"
        print(f"{index:4d}: {verdict:4s} relMSE {rel_mse:.2e} (noise {noise:.2e}, ours/Mitsuba "
              f"{row['noise_ratio']:.2f}), mean rel diff " + " ".join(f"{x:+.2%}" for x in mean_rel),
              flush=True)
        if row["flag"]:
            flagged.append(index)
            mitsuba().Bitmap(ref.astype(np.float32)).write(str(d / "mitsuba.exr"))
            side_by_side(d / "compare.png", ref, ours, 1.0)
        elif not args.keep:
            shutil.rmtree(d)
    finish(out, rows, flagged, args.count)


if __name__ == "__main__":
    main()
