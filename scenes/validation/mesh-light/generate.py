"""Writes this scene's two emitting meshes (run once; the OBJ files are committed):
meshes/ring.obj, a torus of 48 x 16 quads with smooth vertex normals (a ring light), and
meshes/tube.obj, a bent tube of 40 x 8 quads without normals (a neon tube along a wall)."""
import math
from pathlib import Path

HERE = Path(__file__).resolve().parent


def write(path, verts, normals, faces):
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in verts]
    lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in normals]
    for f in faces:
        if normals:
            lines.append("f " + " ".join(f"{i + 1}//{i + 1}" for i in f))
        else:
            lines.append("f " + " ".join(str(i + 1) for i in f))
    path.write_text("\n".join(lines) + "\n")


def ring(rings=48, sides=16, big=1.0, small=0.12):
    verts, normals, faces = [], [], []
    for i in range(rings):
        a = 2 * math.pi * i / rings
        for j in range(sides):
            b = 2 * math.pi * j / sides
            r = big + small * math.cos(b)
            verts.append((r * math.cos(a), small * math.sin(b), r * math.sin(a)))
            normals.append((math.cos(b) * math.cos(a), math.sin(b), math.cos(b) * math.sin(a)))
    at = lambda i, j: (i % rings) * sides + (j % sides)
    for i in range(rings):
        for j in range(sides):
            faces.append((at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)))
    return verts, normals, faces


def tube(segments=40, sides=8, length=3.2, radius=0.04, bend=0.35):
    """Along x from -length/2 to length/2, sagging by `bend` in y at its middle."""
    verts, faces = [], []
    for i in range(segments + 1):
        t = i / segments
        x = (t - 0.5) * length
        y = -bend * 4 * t * (1 - t)
        # Tangent of the sag, to orient the cross-section.
        dy = -bend * 4 * (1 - 2 * t) / length
        tx, ty = 1 / math.hypot(1, dy), dy / math.hypot(1, dy)
        nx, ny = -ty, tx
        for j in range(sides):
            b = 2 * math.pi * j / sides
            c, s = math.cos(b), math.sin(b)
            verts.append((x + radius * c * nx, y + radius * c * ny, radius * s))
    at = lambda i, j: i * sides + (j % sides)
    for i in range(segments):
        for j in range(sides):
            faces.append((at(i, j), at(i, j + 1), at(i + 1, j + 1), at(i + 1, j)))
    # Caps.
    for i in (0, segments):
        cap = [at(i, j) for j in range(sides)]
        faces.append(tuple(reversed(cap) if i == segments else cap))
    return verts, [], faces


write(HERE / "meshes" / "ring.obj", *ring())
write(HERE / "meshes" / "tube.obj", *tube())
