#!/usr/bin/env python3
"""The `--extended` scene generator of fuzz_mitsuba.py: random scenes with the plugins and
parameters the base generator leaves out.

Bitmap textures (PNG and EXR; reflectance, roughness, blend weight, mask opacity, principled
parameters, area-emitter radiance; random `filter_type`, `wrap_mode`, `to_uv`), `normalmap`
and `bumpmap` over random models, anisotropic and Beckmann microfacets, conductors by `eta` /
`k`, named and explicit IORs (`ext_ior` too), `<spectrum>` values, nonlinear plastics, OBJ and
PLY meshes (with and without normals, `face_normals`, `flip_normals`), `shapegroup` +
`instance`, `matrix` transforms, an `envmap` sky, thin-lens, orthographic and off-centre
perspective cameras, and the other reconstruction filters. Every scene also draws from the
base generator's materials, shapes and lights, and writes its images and meshes next to its
scene.xml (a function of (seed, index), like the scene).

Not a script of its own: `python3 scripts/fuzz_mitsuba.py --extended ...`.
"""

import math
import random

import numpy as np

from fuzz_mitsuba import RES, area_rectangle, light, material, rgb, shape, spot_light
from make_scene_assets import (icosphere, grid, write_exr_rgb32, write_obj, write_ply_binary, write_ply_properties,
                                write_png_rgb8, write_ppm_rgb8, write_serialized)

TEX = 32  # texture side (pixels)


class Assets:
    """Writes a scene's files into its folder under fresh names (tex0.png, mesh1.obj, ...)."""

    def __init__(self, folder, r):
        self.folder, self.r, self.count = folder, r, 0

    def name(self, ext):
        self.count += 1
        return f"asset{self.count}.{ext}"

    def field(self):
        """A smooth random scalar field on the unit square, f(u, v) in [0, 1]."""
        r = self.r
        waves = [(r.uniform(-6, 6), r.uniform(-6, 6), r.uniform(0, 2 * math.pi)) for _ in range(3)]
        blobs = [(r.uniform(0, 1), r.uniform(0, 1), r.uniform(0.05, 0.25)) for _ in range(3)]

        def f(u, v):
            s = sum(math.sin(2 * math.pi * (a * u + b * v) / 4 + p) for a, b, p in waves) / 6 + 0.5
            s += sum(math.exp(-((u - x) ** 2 + (v - y) ** 2) / (2 * w * w)) for x, y, w in blobs) / 3
            return min(max(s / 1.5, 0.0), 1.0)
        return f

    def colour_png(self, width=TEX, height=TEX):
        """An sRGB colour pattern: two random colours mixed by a smooth field, with a dark grid."""
        f, c0, c1 = self.field(), [self.r.randint(20, 235) for _ in range(3)], [self.r.randint(20, 235) for _ in range(3)]
        cells = self.r.choice([0, 4, 8])

        def pixel(x, y):
            if cells and (x % (width // cells) == 0 or y % (height // cells) == 0):
                return (15, 15, 15)
            t = f((x + 0.5) / width, (y + 0.5) / height)
            return tuple(round(a + (b - a) * t) for a, b in zip(c0, c1))
        # Every third asset a binary PPM: the same 8-bit sRGB texels in Mitsuba's other
        # container (chosen by the asset count, so the random stream stays as it was).
        if self.count % 3 == 2:
            path = self.name("ppm")
            write_ppm_rgb8(self.folder / path, width, height, pixel)
        else:
            path = self.name("png")
            write_png_rgb8(self.folder / path, width, height, pixel)
        return path

    def grey_png(self, lo=0, hi=255):
        """A grey PNG of a smooth field between lo and hi (8-bit values)."""
        f = self.field()

        def pixel(x, y):
            g = round(lo + (hi - lo) * f((x + 0.5) / TEX, (y + 0.5) / TEX))
            return (g, g, g)
        path = self.name("png")
        write_png_rgb8(self.folder / path, TEX, TEX, pixel)
        return path

    def normal_png(self):
        """A tangent-space normal map: the normals of a random height field (8-bit, raw)."""
        f, s = self.field(), self.r.uniform(0.5, 4)

        def pixel(x, y):
            u, v, e = (x + 0.5) / TEX, (y + 0.5) / TEX, 1 / TEX
            dx = (f(u + e, v) - f(u - e, v)) / (2 * e)
            dy = (f(u, v + e) - f(u, v - e)) / (2 * e)
            n = np.array([-s * dx / 8, s * dy / 8, 1.0])
            n /= np.linalg.norm(n)
            return tuple(round(255 * (c + 1) / 2) for c in n)
        path = self.name("png")
        write_png_rgb8(self.folder / path, TEX, TEX, pixel)
        return path

    def radiance_exr(self, lo, hi):
        """A float EXR of colours between lo and hi per channel (emitter radiance)."""
        f, g = self.field(), self.field()
        tint = [self.r.uniform(0.3, 1) for _ in range(3)]

        def pixel(x, y):
            u, v = (x + 0.5) / TEX, (y + 0.5) / TEX
            return tuple(t * (lo + (hi - lo) * (f(u, v) if k != 1 else g(u, v))) for k, t in enumerate(tint))
        path = self.name("exr")
        write_exr_rgb32(self.folder / path, TEX, TEX, pixel)
        return path

    def sky_exr(self):
        """A latitude-longitude sky: a smooth gradient and a small bright sun."""
        r = self.r
        w, h = 64, 32
        sun_u, sun_v, sun_w = r.uniform(0, 1), r.uniform(0.1, 0.45), r.uniform(0.02, 0.06)
        sun = r.uniform(20, 200)
        top, bottom = [r.uniform(0.2, 1) for _ in range(3)], [r.uniform(0.0, 0.3) for _ in range(3)]

        def pixel(x, y):
            u, v = (x + 0.5) / w, (y + 0.5) / h
            du = min(abs(u - sun_u), 1 - abs(u - sun_u))
            s = sun if du * du + (v - sun_v) ** 2 < sun_w * sun_w else 0.0
            return tuple(b + (t - b) * (1 - v) + s for t, b in zip(top, bottom))
        path = self.name("exr")
        write_exr_rgb32(self.folder / path, w, h, pixel)
        return path

    def sphere_mesh(self, colours=False):
        """An icosphere: OBJ (with uvs from the sphere's angles; normals or not), PLY
        (normals, no uvs) or Mitsuba `.serialized` (normals and uvs or not); with `colours` a
        PLY with float vertex colours (`vertex_color` for `mesh_attribute`) instead."""
        r = self.r
        pos, tris = icosphere(r.randint(1, 2))
        uv = [(0.5 + math.atan2(p[0], p[2]) / (2 * math.pi), math.acos(max(-1, min(1, p[1]))) / math.pi) for p in pos]
        if colours:
            f, g = self.field(), self.field()
            values = [[f((x + 1) / 2, (y + 1) / 2) for x, y, _ in pos], [g((x + 1) / 2, (z + 1) / 2) for x, _, z in pos],
                      [f((z + 1) / 2, (y + 1) / 2) for _, y, z in pos]]
            path = self.name("ply")
            write_ply_properties(self.folder / path, pos, tris,
                                 [("float", c, v) for c, v in zip(("red", "green", "blue"), values)], [],
                                 "fuzz icosphere with vertex colours")
            return "ply", path
        kind = r.choice(["obj", "ply", "serialized"])
        if kind == "serialized":
            path = self.name("serialized")
            with_attrs = r.random() < 0.5
            write_serialized(self.folder / path, [("s", pos, pos if with_attrs else None, uv if with_attrs else None,
                                                   tris, False)])
            return "serialized", path
        if kind == "obj":
            path = self.name("obj")
            normals = pos if r.random() >= 0.5 else None
            write_obj(self.folder / path, pos, normals, uv, tris, "fuzz icosphere")
            return "obj", path
        path = self.name("ply")
        write_ply_binary(self.folder / path, pos, pos, tris, "fuzz icosphere")
        return "ply", path

    def terrain_mesh(self):
        """A bumpy grid over [-1, 1]^2 (z up to 0.3) with uvs, as OBJ."""
        f = self.field()
        pos, tris = grid(8)
        pos = [(x, y, 0.3 * f((x + 1) / 2, (y + 1) / 2)) for x, y, _ in pos]
        uv = [((x + 1) / 2, (y + 1) / 2) for x, y, _ in pos]
        path = self.name("obj")
        write_obj(self.folder / path, pos, None, uv, tris, "fuzz terrain")
        return path


def bitmap(a, name, path, raw=False):
    """A bitmap texture element named `name` with random filtering, wrapping and to_uv."""
    r = a.r
    extra = f'<string name="filter_type" value="{r.choice(["bilinear", "nearest"])}"/>'
    extra += f'<string name="wrap_mode" value="{r.choice(["repeat", "mirror", "clamp"])}"/>'
    if raw:
        extra += '<boolean name="raw" value="true"/>'
    if r.random() < 0.5:
        extra += (f'<transform name="to_uv"><scale x="{r.uniform(0.5, 3):.3f}" y="{r.uniform(0.5, 3):.3f}"/>'
                  f'<translate x="{r.uniform(-0.5, 0.5):.3f}" y="{r.uniform(-0.5, 0.5):.3f}"/></transform>')
    return f'<texture type="bitmap" name="{name}"><string name="filename" value="{path}"/>{extra}</texture>'


def grey(a, name, lo, hi):
    """A grey bitmap (raw) whose values lie in [lo, hi] (0..1), named `name`."""
    return bitmap(a, name, a.grey_png(round(255 * lo), round(255 * hi)), raw=True)


def spectrum(r):
    """A reflectance as a `<spectrum>`: a constant or a wavelength:value list."""
    if r.random() < 0.3:
        return f'<spectrum name="reflectance" value="{r.uniform(0.1, 0.9):.3f}"/>'
    pts = ", ".join(f"{w}:{r.uniform(0.05, 0.95):.3f}" for w in range(400, 701, 50))
    return f'<spectrum name="reflectance" value="{pts}"/>'


def distribution(r):
    return f'<string name="distribution" value="{r.choice(["ggx", "beckmann"])}"/>'


def ext_material(a, environment, allow_delta=True):
    """A random BSDF with a texture, a map or a parameter form the base generator lacks;
    sometimes one of the base generator's."""
    r = a.r
    kinds = ["bitmap", "spectrum", "aniso", "textured-rough", "eta-k", "named-ior", "rough-ior",
             "plastic-nonlinear", "principled-tex", "blend-tex", "normalmap", "bumpmap", "base",
             "specular-tex", "twosided-two"]
    if environment:
        kinds.append("mask-tex")
    k = r.choice(kinds)
    if not allow_delta and k in ("eta-k", "named-ior", "plastic-nonlinear", "specular-tex"):
        k = "bitmap"
    if k == "bitmap":
        return f'<bsdf type="diffuse">{bitmap(a, "reflectance", a.colour_png())}</bsdf>'
    if k == "spectrum":
        return f'<bsdf type="diffuse">{spectrum(r)}</bsdf>'
    if k == "aniso":
        return (f'<bsdf type="roughconductor">{distribution(r)}'
                f'<string name="material" value="{r.choice(["Au", "Cu", "Al", "Ag", "CuO", "W", "Hg"])}"/>'
                f'<float name="alpha_u" value="{r.uniform(0.03, 0.5):.3f}"/>'
                f'<float name="alpha_v" value="{r.uniform(0.03, 0.5):.3f}"/></bsdf>')
    if k == "textured-rough":
        if r.random() < 0.5:
            return (f'<bsdf type="roughconductor">{distribution(r)}<string name="material" value="Al"/>'
                    f'{grey(a, "alpha", 0.05, 0.6)}</bsdf>')
        return (f'<bsdf type="roughdielectric">{distribution(r)}'
                f'<float name="int_ior" value="{r.uniform(1.3, 1.7):.3f}"/>{grey(a, "alpha", 0.05, 0.5)}</bsdf>')
    if k == "eta-k":
        return (f'<bsdf type="conductor"><rgb name="eta" value="{rgb(r, 0.1, 3)}"/>'
                f'<rgb name="k" value="{rgb(r, 0.5, 5)}"/>'
                f'<rgb name="specular_reflectance" value="{rgb(r, 0.5, 1)}"/></bsdf>')
    if k == "named-ior":
        kind = r.choice(["dielectric", "thindielectric"])
        return (f'<bsdf type="{kind}"><string name="int_ior" value="{r.choice(["bk7", "water", "diamond", "pyrex", "acetone"])}"/>'
                f'<string name="ext_ior" value="{r.choice(["air", "vacuum"])}"/></bsdf>')
    if k == "rough-ior":
        if r.random() < 0.5:
            return (f'<bsdf type="roughdielectric">{distribution(r)}'
                    f'<float name="int_ior" value="{r.uniform(1.2, 1.8):.3f}"/>'
                    f'<float name="ext_ior" value="{r.uniform(1.0, 1.15):.3f}"/>'
                    f'<float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>')
        return (f'<bsdf type="roughplastic">{distribution(r)}'
                f'<rgb name="diffuse_reflectance" value="{rgb(r)}"/>'
                f'<float name="int_ior" value="{r.uniform(1.3, 1.8):.3f}"/>'
                f'<boolean name="nonlinear" value="{r.choice(["true", "false"])}"/>'
                f'<float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>')
    if k == "plastic-nonlinear":
        return (f'<bsdf type="plastic">{bitmap(a, "diffuse_reflectance", a.colour_png())}'
                f'<boolean name="nonlinear" value="true"/>'
                f'<float name="int_ior" value="{r.uniform(1.3, 1.7):.3f}"/></bsdf>')
    if k == "principled-tex":
        params = [bitmap(a, "base_color", a.colour_png()), grey(a, "roughness", 0.15, 0.9)]
        for name, lo, hi in [("metallic", 0, 1), ("spec_trans", 0, 1), ("sheen", 0, 1),
                             ("clearcoat", 0, 1), ("anisotropic", 0, 0.8)]:
            if r.random() < 0.4:
                params.append(f'<float name="{name}" value="{r.uniform(lo, hi):.3f}"/>')
        return f'<bsdf type="principled">{"".join(params)}</bsdf>'
    if k == "blend-tex":
        x = f'<bsdf type="diffuse">{bitmap(a, "reflectance", a.colour_png())}</bsdf>'
        y = (f'<bsdf type="roughconductor">{distribution(r)}'
             f'<float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>')
        return f'<bsdf type="blendbsdf">{grey(a, "weight", 0.1, 0.9)}{x}{y}</bsdf>'
    if k == "specular-tex":
        # Colour textures on the specular terms (Mitsuba reads plastics' by their mean).
        kind = r.choice(["dielectric", "thindielectric", "roughdielectric", "conductor", "plastic"])
        tex = bitmap(a, "specular_reflectance", a.colour_png())
        if kind == "conductor":
            return f'<bsdf type="conductor"><string name="material" value="Au"/>{tex}</bsdf>'
        if kind == "plastic":
            return f'<bsdf type="plastic"><rgb name="diffuse_reflectance" value="{rgb(r)}"/>{tex}</bsdf>'
        extra = bitmap(a, "specular_transmittance", a.colour_png()) if r.random() < 0.7 else ""
        if kind == "roughdielectric":
            extra += (f'{distribution(r)}<float name="alpha_u" value="{r.uniform(0.05, 0.4):.3f}"/>'
                      f'<float name="alpha_v" value="{r.uniform(0.05, 0.4):.3f}"/>'
                      f'<boolean name="sample_visible" value="{r.choice(["true", "false"])}"/>')
        return f'<bsdf type="{kind}"><float name="int_ior" value="{r.uniform(1.3, 1.7):.3f}"/>{tex}{extra}</bsdf>'
    if k == "twosided-two":
        # A different model on each side (neither may transmit, as in Mitsuba).
        front = ext_material(a, False, allow_delta=False)
        back = ext_material(a, False, allow_delta=False)
        if any(t in front + back for t in ("dielectric", "twosided", "mask", "spec_trans", "blendbsdf")):
            front = f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf>'
            back = (f'<bsdf type="roughconductor">{distribution(r)}'
                    f'<float name="alpha" value="{r.uniform(0.05, 0.4):.3f}"/></bsdf>')
        return f'<bsdf type="twosided">{front}{back}</bsdf>'
    if k == "mask-tex":
        inner = ext_material(a, False, allow_delta=False)
        return f'<bsdf type="mask">{grey(a, "opacity", 0.2, 1.0)}{inner}</bsdf>'
    if k in ("normalmap", "bumpmap"):
        inner = r.choice([
            f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf>',
            f'<bsdf type="roughconductor">{distribution(r)}<float name="alpha" value="{r.uniform(0.1, 0.4):.3f}"/></bsdf>',
            f'<bsdf type="roughplastic"><rgb name="diffuse_reflectance" value="{rgb(r)}"/><float name="alpha" value="{r.uniform(0.1, 0.4):.3f}"/></bsdf>',
            f'<bsdf type="principled"><rgb name="base_color" value="{rgb(r)}"/><float name="roughness" value="{r.uniform(0.2, 0.8):.3f}"/></bsdf>',
        ])
        flags = ""
        if r.random() < 0.3:
            flags += '<boolean name="flip_invalid_normals" value="false"/>'
        if r.random() < 0.3:
            flags += '<boolean name="use_shadowing_function" value="false"/>'
        if k == "normalmap":
            return f'<bsdf type="normalmap">{bitmap(a, "normalmap", a.normal_png(), raw=True)}{flags}{inner}</bsdf>'
        tex = bitmap(a, "", a.grey_png(), raw=True).replace(' name=""', "")
        return (f'<bsdf type="bumpmap">{tex}<float name="scale" value="{r.uniform(-0.5, 1.0):.3f}"/>'
                f'{flags}{inner}</bsdf>')
    return material(r, allow_delta, environment)


def ext_shape(a, bsdf, ids):
    """A random object: a mesh, a group of instances, a `matrix`-placed cube, or a base shape."""
    r = a.r
    x, z = r.uniform(-1.2, 1.2), r.uniform(-1.2, 1.2)
    k = r.choice(["sphere-mesh", "terrain", "instances", "matrix-cube", "base"])
    if k == "sphere-mesh":
        colours = r.random() < 0.25
        kind, path = a.sphere_mesh(colours)
        if colours:
            bsdf = ('<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance">'
                    '<string name="name" value="vertex_color"/></texture></bsdf>')
        s = r.uniform(0.25, 0.5)
        flags = ""
        if r.random() < 0.3:
            flags += '<boolean name="face_normals" value="true"/>'
        if r.random() < 0.2:
            flags += '<boolean name="flip_normals" value="true"/>'
        return (f'<shape type="{kind}"><string name="filename" value="{path}"/>{flags}'
                f'<transform name="to_world"><scale value="{s:.3f}"/><rotate y="1" angle="{r.uniform(0, 360):.1f}"/>'
                f'<translate x="{x:.3f}" y="{s + 0.01:.3f}" z="{z:.3f}"/></transform>{bsdf}</shape>')
    if k == "terrain":
        s = r.uniform(0.3, 0.7)
        return (f'<shape type="obj"><string name="filename" value="{a.terrain_mesh()}"/>'
                f'<transform name="to_world"><scale value="{s:.3f}"/><rotate x="1" angle="{r.uniform(-90, -30):.1f}"/>'
                f'<rotate y="1" angle="{r.uniform(-60, 60):.1f}"/><translate x="{x:.3f}" y="{r.uniform(0.4, 1.0):.3f}" z="{z:.3f}"/>'
                f'</transform>{bsdf}</shape>')
    if k == "instances":
        gid = f"group{len(ids)}"
        ids.append(gid)
        s = r.uniform(0.15, 0.3)
        group = (f'<shape type="shapegroup" id="{gid}">'
                 f'<shape type="sphere"><point name="center" x="0" y="{s:.3f}" z="0"/><float name="radius" value="{s:.3f}"/>{bsdf}</shape>'
                 f'<shape type="cube"><transform name="to_world"><scale value="{s * 0.7:.3f}"/>'
                 f'<translate x="{2.2 * s:.3f}" y="{0.7 * s + 0.01:.3f}" z="0"/></transform>'
                 f'<bsdf type="diffuse"><rgb name="reflectance" value="{rgb(r)}"/></bsdf></shape></shape>')
        if r.random() < 0.5:  # a mesh without uvs (parameterised by its vertex order)
            kind, path = a.sphere_mesh()
            group = group.replace("</shape></shape>", f'</shape><shape type="{kind}"><string name="filename" value="{path}"/>'
                                  f'<transform name="to_world"><scale value="{s:.3f}"/><translate x="{-2.2 * s:.3f}" y="{s + 0.01:.3f}"/>'
                                  f'</transform>{bsdf}</shape></shape>', 1)
        insts = []
        for _ in range(r.randint(1, 3)):
            mirror = r.choice(['<scale x="-1"/>', '<scale z="-1"/>', "", ""])
            insts.append(f'<shape type="instance"><ref id="{gid}"/><transform name="to_world">{mirror}'
                         f'<scale value="{r.uniform(0.6, 1.5):.3f}"/><rotate y="1" angle="{r.uniform(0, 360):.1f}"/>'
                         f'<translate x="{r.uniform(-1.2, 1.2):.3f}" y="0.01" z="{r.uniform(-1.2, 1.2):.3f}"/></transform></shape>')
        return group + "".join(insts)
    if k == "matrix-cube":
        # A rotation about a random axis with a non-uniform scale, written as one 4x4 matrix.
        axis = np.array([r.gauss(0, 1) for _ in range(3)])
        axis /= np.linalg.norm(axis)
        t = r.uniform(0, math.pi)
        kx = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        rot = np.eye(3) + math.sin(t) * kx + (1 - math.cos(t)) * kx @ kx
        m = rot @ np.diag([r.uniform(0.15, 0.4) for _ in range(3)])
        m4 = np.eye(4)
        m4[:3, :3], m4[:3, 3] = m, [x, r.uniform(0.6, 1.0), z]
        values = " ".join(f"{v:.6f}" for v in m4.flatten())
        return f'<shape type="cube"><transform name="to_world"><matrix value="{values}"/></transform>{bsdf}</shape>'
    base = shape(r, bsdf)
    if r.random() < 0.2:  # the inside becomes the outside (glass turns inside out, ...)
        base = base.replace(">", '><boolean name="flip_normals" value="true"/>', 1)
    return base


def ext_light(a, allow_environment, area_only=False):
    """A textured area light, an envmap, or a base light (with `area_only`: no delta light)."""
    r = a.r
    kinds = ["textured-area", "base"] + (["envmap"] if allow_environment else [])
    if not area_only:
        kinds += ["textured-spot", "projector"]
    k = r.choice(kinds)
    if k == "textured-spot":  # a slide projected by a spot (the cutoff cone spans the texture)
        return spot_light(r, turn=True, slide=lambda: bitmap(a, "texture", a.colour_png()))
    if k == "projector":  # a pinhole projecting an image, the perspective camera's reciprocal
        return projector(a)
    if k == "textured-area":
        return area_rectangle(r, lambda: bitmap(a, "radiance", a.radiance_exr(1, 12)))
    if k == "envmap":
        return (f'<emitter type="envmap"><string name="filename" value="{a.sky_exr()}"/>'
                f'<float name="scale" value="{r.uniform(0.3, 1.5):.3f}"/>'
                f'<transform name="to_world"><rotate y="1" angle="{r.uniform(0, 360):.1f}"/></transform></emitter>')
    return light(r, allow_environment, area_only)


def projector(a):
    """Mitsuba's `projector`: a turned pinhole above the scene aimed at the origin, projecting a
    colour image (its aspect ratio sets the frustum's) or a constant, with a field of view on a
    random axis or a focal length."""
    r = a.r
    spin = f'<rotate z="1" angle="{r.uniform(0, 360):.1f}"/>'
    look = (f'<lookat origin="{r.uniform(-2, 2):.3f}, {r.uniform(2, 3.5):.3f}, {r.uniform(-2, 2):.3f}" '
            f'target="{r.uniform(-0.5, 0.5):.3f}, 0, {r.uniform(-0.5, 0.5):.3f}"/>')
    if r.random() < 0.8:
        width, height = r.choice([(TEX, TEX), (TEX, TEX // 2), (TEX // 2, TEX), (TEX, 3 * TEX // 4)])
        irradiance = bitmap(a, "irradiance", a.colour_png(width, height))
    else:
        irradiance = f'<rgb name="irradiance" value="{rgb(r, 0.3, 1)}"/>'
    if r.random() < 0.8:
        fov = (f'<float name="fov" value="{r.uniform(20, 60):.1f}"/>'
               f'<string name="fov_axis" value="{r.choice(["x", "y", "smaller", "larger", "diagonal"])}"/>')
    else:
        fov = f'<string name="focal_length" value="{r.uniform(25, 80):.0f}mm"/>'
    return (f'<emitter type="projector"><transform name="to_world">{spin}{look}</transform>{irradiance}'
            f'<float name="scale" value="{r.uniform(1, 6):.3f}"/>{fov}</emitter>')


def sensor(r):
    """A perspective (maybe off-centre), thin-lens or orthographic camera with a random filter."""
    elev, azim, dist = r.uniform(10, 55), r.uniform(0, 360), r.uniform(3.5, 6)
    e, az = math.radians(elev), math.radians(azim)
    origin = (dist * math.cos(e) * math.sin(az), dist * math.sin(e), dist * math.cos(e) * math.cos(az))
    # Without `up` Mitsuba completes the view direction to a frame of its own choosing.
    up = "" if r.random() < 0.2 else ' up="0, 1, 0"'
    look = f'<lookat origin="{origin[0]:.3f}, {origin[1]:.3f}, {origin[2]:.3f}" target="0, 0.3, 0"{up}/>'
    kind = r.choice(["perspective", "thinlens", "orthographic"])
    params = ""
    if r.random() < 0.3:  # may cut into the objects nearest the camera
        params += f'<float name="near_clip" value="{r.uniform(0.01, 0.8) * dist:.3f}"/>'
    if kind != "orthographic" and r.random() < 0.4:
        params += f'<string name="fov_axis" value="{r.choice(["x", "y", "diagonal", "smaller", "larger"])}"/>'
    if kind == "perspective":
        params += f'<float name="fov" value="{r.uniform(30, 60):.1f}"/>'
        if r.random() < 0.5:
            params += (f'<float name="principal_point_offset_x" value="{r.uniform(-0.2, 0.2):.3f}"/>'
                       f'<float name="principal_point_offset_y" value="{r.uniform(-0.2, 0.2):.3f}"/>')
        transform = look
    elif kind == "thinlens":
        params += (f'<float name="fov" value="{r.uniform(30, 60):.1f}"/>'
                   f'<float name="aperture_radius" value="{r.uniform(0.02, 0.15):.3f}"/>'
                   f'<float name="focus_distance" value="{dist * r.uniform(0.7, 1.2):.3f}"/>')
        transform = look
    else:
        s = r.uniform(1.2, 2.2)
        transform = f'<scale x="{s:.3f}" y="{s:.3f}"/>{look}'
    rfilter = r.choice(['<rfilter type="box"/>'] * 3 + [
        f'<rfilter type="gaussian"><float name="stddev" value="{r.uniform(0.3, 0.6):.2f}"/></rfilter>',
        '<rfilter type="tent"/>', '<rfilter type="mitchell"/>'])
    film = ""
    # Non-square films (where fov_axis x / y / smaller / larger differ), 4-pixel multiples.
    height = "$res" if r.random() < 0.6 else str(r.choice([20, 24, 40, 48]))
    if r.random() < 0.2:
        film += '<boolean name="sample_border" value="true"/>'
    if r.random() < 0.2:  # a crop window (a multiple of 4 pixels wide, for the comparison)
        film += (f'<integer name="crop_offset_x" value="{r.randint(0, 8)}"/><integer name="crop_offset_y" value="{r.randint(0, 4)}"/>'
                 f'<integer name="crop_width" value="{4 * r.randint(4, 6)}"/><integer name="crop_height" value="{4 * r.randint(3, 4)}"/>')
    return f"""<sensor type="{kind}">
        {params}
        <transform name="to_world">{transform}</transform>
        <sampler type="independent"><integer name="sample_count" value="$spp"/></sampler>
        <film type="hdrfilm"><integer name="width" value="$res"/><integer name="height" value="{height}"/>{film}{rfilter}</film>
    </sensor>"""


def extended_scene_xml(seed, index, folder, masks=True, lights="all", delta_materials=True):
    """Scene `index` of generator seed `seed` with its assets written into `folder`; the
    options as the base generator's: without `masks` no `mask` BSDF, `lights="area"` area lights
    and skies only, without `delta_materials` no smooth (delta) BSDF."""
    r = random.Random(seed * 1_000_033 + index + 17)
    a = Assets(folder, r)
    cam = sensor(r)
    area_only = lights == "area"
    first = ext_light(a, True, area_only)
    env = lambda l: 'type="constant"' in l or 'type="envmap"' in l  # noqa: E731
    lights = [first] + [ext_light(a, not env(first), area_only) for _ in range(r.randint(0, 1))]
    environment = any(env(l) for l in lights) and masks
    floor = ext_material(a, environment, allow_delta=False)
    ids = []
    objects = "\n    ".join(ext_shape(a, ext_material(a, environment, delta_materials), ids) for _ in range(r.randint(1, 3)))
    lights = "\n    ".join(lights)
    return f"""<scene version="3.0.0">
    <default name="spp" value="64"/>
    <default name="res" value="{RES}"/>
    <integrator type="path"><integer name="max_depth" value="{r.randint(2, 8)}"/></integrator>
    {cam}
    <shape type="rectangle"><transform name="to_world"><scale value="4"/><rotate x="1" angle="-90"/></transform>{floor}</shape>
    {objects}
    {lights}
</scene>
"""
