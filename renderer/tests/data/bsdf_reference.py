#!/usr/bin/env python3
"""Generate `bsdf_reference.json` (next to this script): BSDF values computed by Mitsuba 3
itself, which the BSDF tests (`renderer/src/bsdf/tests.rs`) compare against (eval, pdf in both
transport modes at random direction pairs, directional albedos by 10^6-sample Monte Carlo, and
`eval_diffuse_reflectance` from one front and one back direction). Rerunning it on another CPU
changes the last digits of the JIT's results; the tests' tolerances are far wider.

Every number is an f32 value of Mitsuba's, written exactly: the shortest decimal of its f64
value, which reads back to the same f32 (see `reference_json.py`).

Usage (needs `pip install mitsuba`; development only, never a runtime dependency):
    python3 renderer/tests/data/bsdf_reference.py > renderer/tests/data/bsdf_reference.json
"""
import sys

import numpy as np
import mitsuba as mi

from reference_json import f32, f32s, write_json

mi.set_variant("llvm_ad_rgb")
import drjit as dr

# (name, Mitsuba dict, Rust constructor expression, two-sided directions?)
AU_ETA = [0.143, 0.374, 1.442]
AU_K = [3.983, 2.385, 1.603]


def rgb(v):
    return {"type": "rgb", "value": v}


CASES = [
    ("diffuse", {"type": "diffuse", "reflectance": rgb([0.8, 0.5, 0.2])},
     "diffuse(rgb(0.8, 0.5, 0.2))", False),
    ("roughconductor beckmann 0.3 Au",
     {"type": "roughconductor", "distribution": "beckmann", "alpha": 0.3, "eta": rgb(AU_ETA), "k": rgb(AU_K)},
     "rough_conductor(rough(Beckmann, 0.3, 0.3), gold())", False),
    ("roughconductor ggx aniso 0.1/0.4 Au",
     {"type": "roughconductor", "distribution": "ggx", "alpha_u": 0.1, "alpha_v": 0.4, "eta": rgb(AU_ETA), "k": rgb(AU_K)},
     "rough_conductor(rough(Ggx, 0.1, 0.4), gold())", False),
    ("roughconductor beckmann aniso 0.5/0.2 none",
     {"type": "roughconductor", "distribution": "beckmann", "alpha_u": 0.5, "alpha_v": 0.2},
     "rough_conductor(rough(Beckmann, 0.5, 0.2), None)", False),
    ("roughdielectric beckmann 0.3 1.5",
     {"type": "roughdielectric", "distribution": "beckmann", "alpha": 0.3, "int_ior": 1.5, "ext_ior": 1.0},
     "rough_dielectric(rough(Beckmann, 0.3, 0.3), 1.5)", True),
    ("roughdielectric ggx aniso 0.15/0.45 1.33",
     {"type": "roughdielectric", "distribution": "ggx", "alpha_u": 0.15, "alpha_v": 0.45, "int_ior": 1.33, "ext_ior": 1.0},
     "rough_dielectric(rough(Ggx, 0.15, 0.45), 1.33)", True),
    ("plastic 1.49",
     {"type": "plastic", "int_ior": 1.49, "ext_ior": 1.0, "diffuse_reflectance": rgb([0.5, 0.3, 0.1])},
     "plastic(1.49, rgb(0.5, 0.3, 0.1), false)", False),
    ("plastic nonlinear 1.6",
     {"type": "plastic", "int_ior": 1.6, "ext_ior": 1.0, "nonlinear": True, "diffuse_reflectance": rgb([0.9, 0.6, 0.2])},
     "plastic(1.6, rgb(0.9, 0.6, 0.2), true)", False),
    ("roughplastic ggx 0.3",
     {"type": "roughplastic", "distribution": "ggx", "alpha": 0.3, "int_ior": 1.49, "ext_ior": 1.0, "diffuse_reflectance": rgb([0.5, 0.4, 0.3])},
     "rough_plastic(rough(Ggx, 0.3, 0.3), 1.49, rgb(0.5, 0.4, 0.3), false)", False),
    ("roughplastic beckmann 0.15 nonlinear",
     {"type": "roughplastic", "distribution": "beckmann", "alpha": 0.15, "int_ior": 1.5, "ext_ior": 1.0, "nonlinear": True, "diffuse_reflectance": rgb([0.8, 0.2, 0.5])},
     "rough_plastic(rough(Beckmann, 0.15, 0.15), 1.5, rgb(0.8, 0.2, 0.5), true)", False),
    ("twosided diffuse / roughconductor",
     {"type": "twosided",
      "a": {"type": "diffuse", "reflectance": rgb([0.6, 0.6, 0.6])},
      "b": {"type": "roughconductor", "distribution": "ggx", "alpha": 0.3, "eta": rgb(AU_ETA), "k": rgb(AU_K)}},
     "two_sided(diffuse(constant(0.6)), rough_conductor(rough(Ggx, 0.3, 0.3), gold()))", True),
    ("dielectric 1.5", {"type": "dielectric", "int_ior": 1.5, "ext_ior": 1.0},
     "dielectric(1.5)", True),
    ("thindielectric 1.5", {"type": "thindielectric", "int_ior": 1.5, "ext_ior": 1.0},
     "thin_dielectric(1.5)", True),
    ("conductor Au", {"type": "conductor", "eta": rgb(AU_ETA), "k": rgb(AU_K)},
     "conductor(gold())", False),
    ("principled default", {"type": "principled"},
     "principled(PrincipledParams::default())", True),
    ("principled metallic aniso spec_tint",
     {"type": "principled", "base_color": rgb([0.9, 0.6, 0.3]), "metallic": 0.8, "roughness": 0.35,
      "anisotropic": 0.6, "spec_tint": 0.3},
     "principled(metallic 0.8, roughness 0.35, anisotropic 0.6, spec_tint 0.3)", False),
    ("principled spec_trans eta 1.4",
     {"type": "principled", "base_color": rgb([0.8, 0.9, 0.7]), "spec_trans": 0.7, "roughness": 0.3,
      "eta": 1.4},
     "principled(spec_trans 0.7, roughness 0.3, eta 1.4)", True),
    ("principled clearcoat sheen flatness",
     {"type": "principled", "base_color": rgb([0.2, 0.5, 0.8]), "roughness": 0.6, "sheen": 0.8,
      "sheen_tint": 0.5, "clearcoat": 0.7, "clearcoat_gloss": 0.6, "flatness": 0.4, "specular": 0.3},
     "principled(sheen 0.8/0.5, clearcoat 0.7/0.6, flatness 0.4, specular 0.3)", False),
    ("principled everything, custom rates",
     {"type": "principled", "base_color": rgb([1.0, 0.8, 0.5]), "metallic": 0.3, "specular": 0.6,
      "roughness": 0.2, "spec_tint": 0.4, "anisotropic": 0.5, "sheen": 0.3, "sheen_tint": 0.2,
      "clearcoat": 0.6, "clearcoat_gloss": 0.3, "spec_trans": 0.4,
      "diffuse_reflectance_sampling_rate": 0.5, "main_specular_sampling_rate": 2.0,
      "clearcoat_sampling_rate": 0.3},
     "principled(all parameters, rates 0.5/2/0.3)", True),
    ("principled checkerboard base_color, spec_trans 1, sheen",
     {"type": "principled", "spec_trans": 1.0, "sheen": 0.6, "roughness": 0.45,
      "base_color": {"type": "checkerboard", "color0": rgb([0.1, 0.2, 0.3]),
                     "color1": rgb([0.9, 0.4, 0.6]),
                     "to_uv": mi.ScalarTransform4f().scale([4.0, 2.0, 1.0])}},
     "principled(checkerboard base_color at uv (0.3, 0.3), spec_trans 1, sheen 0.6)", True),
    ("principled eta 1/1.3 (Schlick from the denser side)",
     {"type": "principled", "base_color": rgb([0.7, 0.5, 0.9]), "eta": 1.0 / 1.3, "metallic": 0.4,
      "spec_tint": 0.5, "clearcoat": 0.8, "clearcoat_gloss": 0.5, "spec_trans": 0.5,
      "roughness": 0.4},
     "principled(eta 1/1.3, metallic 0.4, spec_tint 0.5, clearcoat 0.8/0.5, spec_trans 0.5)", True),
    ("principledthin default", {"type": "principledthin"},
     "principled_thin(PrincipledThinParams::default())", True),
    ("principledthin spec_trans diff_trans eta 1.33",
     {"type": "principledthin", "base_color": rgb([0.8, 0.6, 0.3]), "spec_trans": 0.6, "roughness": 0.3,
      "eta": 1.33, "diff_trans": 0.5},
     "principled_thin(spec_trans 0.6, roughness 0.3, eta 1.33, diff_trans 0.5)", True),
    ("principledthin everything, custom rates",
     {"type": "principledthin", "base_color": rgb([0.3, 0.7, 0.9]), "anisotropic": 0.5, "spec_trans": 0.4,
      "spec_tint": 0.3, "sheen": 0.7, "sheen_tint": 0.4, "flatness": 0.5, "diff_trans": 1.3, "eta": 1.6,
      "roughness": 0.45, "diffuse_reflectance_sampling_rate": 0.7,
      "specular_reflectance_sampling_rate": 1.5, "specular_transmittance_sampling_rate": 0.5,
      "diffuse_transmittance_sampling_rate": 2.0},
     "principled_thin(all parameters, rates 0.7/1.5/0.5/2)", True),
    ("principledthin spec_trans 1 roughness 0.2",
     {"type": "principledthin", "base_color": rgb([0.9, 0.9, 0.6]), "spec_trans": 1.0, "roughness": 0.2},
     "principled_thin(spec_trans 1, roughness 0.2)", True),
]

# Surface uv of each case's evaluations (cases not listed: (0, 0)).
CASE_UV = {"principled checkerboard base_color, spec_trans 1, sheen": (0.3, 0.3)}


def rand_dirs(rng, n, two_sided):
    z = rng.uniform(-1 if two_sided else 0, 1, n)
    phi = rng.uniform(0, 2 * np.pi, n)
    s = np.sqrt(np.maximum(0, 1 - z * z))
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], axis=1).astype(np.float32)


def vec(a):
    return mi.Vector3f(mi.Float(a[:, 0].copy()), mi.Float(a[:, 1].copy()), mi.Float(a[:, 2].copy()))


def reference_json(version, names, case_uvs, evals, albedos, diffuse_reflectances):
    """The JSON document's fields, in order (each row a dict of f32 values and indices)."""
    return [
        ("about", f"BSDF values computed by Mitsuba 3 ({version}, llvm_ad_rgb) for "
                  "renderer/src/bsdf/tests.rs; written by bsdf_reference.py in this folder, "
                  "do not edit by hand. Numbers are f32 values written exactly."),
        # Test BSDFs, as constructor expressions of `tests.rs` (index = case id).
        ("cases", names),
        # Surface uv at which each case is evaluated (index = case id).
        ("case_uvs", case_uvs),
        # f radiance and f importance: no cosine.
        ("evals", [{"case": ci, "wo": f32s(wo), "wi": f32s(wi), "f_radiance": f32s(fr),
                    "f_importance": f32s(fi), "pdf": f32(p)}
                   for ci, wo, wi, fr, fi, p in evals]),
        # Mean sample weight and its standard error.
        ("albedos", [{"case": ci, "wo": f32s(w), "importance": mode == "imp",
                      "mean": f32s(mean), "std_error": f32s(err)}
                     for ci, w, mode, mean, err in albedos]),
        # `eval_diffuse_reflectance`.
        ("diffuse_reflectances", [{"case": ci, "wo": f32s(w), "value": f32s(val)}
                                  for ci, w, val in diffuse_reflectances]),
    ]


def main():
    rng = np.random.default_rng(2024)
    evals, albedos = [], []
    for ci, (name, d, rust, two_sided) in enumerate(CASES):
        bsdf = mi.load_dict(d)
        # Direction pairs: half random, half near the specular configuration where glossy
        # lobes have their mass.
        n = 48
        wo = rand_dirs(rng, n, two_sided)
        wi = rand_dirs(rng, n, two_sided)
        for k in range(n // 2):
            mirror = np.array([-wo[k, 0], -wo[k, 1], wo[k, 2]])
            jitter = rng.normal(0, 0.15, 3)
            v = mirror + jitter
            if rng.uniform() < 0.5 and two_sided:
                v[2] = -v[2]  # near the transmitted side too
            wi[k] = (v / np.linalg.norm(v)).astype(np.float32)
        uv = CASE_UV.get(name, (0.0, 0.0))
        si = dr.zeros(mi.SurfaceInteraction3f, n)
        si.wi = vec(wo)
        si.uv = mi.Point2f(uv[0], uv[1])
        out = {}
        for mode_name, mode in (("rad", mi.TransportMode.Radiance), ("imp", mi.TransportMode.Importance)):
            ctx = mi.BSDFContext(mode)
            val = np.array(bsdf.eval(ctx, si, vec(wi)))  # f·|cos θ|, shape (3, n)
            out[mode_name] = np.broadcast_to(val.reshape(3, -1), (3, n))
        pdf = np.broadcast_to(np.array(bsdf.pdf(mi.BSDFContext(), si, vec(wi))).reshape(-1), (n,))
        for k in range(n):
            c = abs(float(wi[k, 2]))
            if c < 1e-3:
                continue
            fr = out["rad"][:, k] / c
            fi = out["imp"][:, k] / c
            evals.append((ci, wo[k], wi[k], fr, fi, pdf[k]))
        # Directional albedos (mean sample weight), 10^6 samples, both modes.
        for t in ([8.0, 45.0, 80.0] + ([135.0, 172.0] if two_sided else [])):
            th = np.radians(t)
            w = np.array([[np.sin(th) * np.cos(0.7), np.sin(th) * np.sin(0.7), np.cos(th)]], dtype=np.float32)
            m = 1_000_000
            si2 = dr.zeros(mi.SurfaceInteraction3f, m)
            si2.wi = mi.Vector3f(float(w[0, 0]), float(w[0, 1]), float(w[0, 2]))
            si2.uv = mi.Point2f(uv[0], uv[1])
            for mode_name, mode in (("rad", mi.TransportMode.Radiance), ("imp", mi.TransportMode.Importance)):
                u = rng.random((3, m)).astype(np.float32)
                bs, weight = bsdf.sample(mi.BSDFContext(mode), si2, mi.Float(u[0]), mi.Point2f(mi.Float(u[1]), mi.Float(u[2])))
                wgt = np.broadcast_to(np.array(weight).reshape(3, -1), (3, m))
                wgt = np.where(np.isfinite(wgt), wgt, 0)
                albedos.append((ci, w[0], mode_name, wgt.mean(axis=1), wgt.std(axis=1) / np.sqrt(m)))

    # eval_diffuse_reflectance (the `albedo` AOV) from fixed directions, front and back.
    diffuse_reflectances = []
    for ci, (name, d, rust, two_sided) in enumerate(CASES):
        bsdf = mi.load_dict(d)
        uv = CASE_UV.get(name, (0.0, 0.0))
        for t in [30.0, 150.0]:
            th = np.radians(t)
            w = [float(np.sin(th) * np.cos(0.4)), float(np.sin(th) * np.sin(0.4)), float(np.cos(th))]
            si = dr.zeros(mi.SurfaceInteraction3f, 1)
            si.wi = mi.Vector3f(*w)
            si.uv = mi.Point2f(uv[0], uv[1])
            val = np.array(bsdf.eval_diffuse_reflectance(si)).reshape(-1)[:3]
            diffuse_reflectances.append((ci, np.array(w, dtype=np.float32), np.broadcast_to(val, (3,))))

    names = [name for name, _, _, _ in CASES]
    case_uvs = [f32s(CASE_UV.get(name, (0.0, 0.0))) for name in names]
    write_json(sys.stdout, reference_json(mi.__version__, names, case_uvs, evals, albedos,
                                          diffuse_reflectances))
    for name, _, rust, _ in CASES:
        print(f"// {rust}", file=sys.stderr)


if __name__ == "__main__":
    main()
