"""Scene XML and mesh cases: `render` (path tracer, and multi-level SPPM for half the cases)."""
import copy
import math
import os
import re
import shutil
import struct
import xml.etree.ElementTree as ET

from . import Case, put, run, byte_mut

NUMS = ['0', '-0', '-1', '1e30', '-1e30', '1e309', '3.4e38', 'nan', 'NaN', 'inf', '-inf', '', ' ', 'abc', '1,2',
        '1, 2, 3, 4', '0x10', '2147483648', '-2147483649', '18446744073709551616', '1e-45', '1e-320', '0.5',
        '100000', '99999999', '4294967295', '-4294967296', '1..2', '+', '1 2 3', '$res', '$nonexistent', '$',
        '1e', '.', '-', 'true']
TAGS = ['float', 'integer', 'rgb', 'spectrum', 'string', 'boolean', 'point', 'vector', 'transform', 'texture',
        'ref', 'bsdf', 'shape', 'emitter', 'sensor', 'film', 'sampler', 'rfilter', 'integrator', 'default',
        'include', 'lookat', 'translate', 'scale', 'rotate', 'matrix', 'medium', 'bogus']
TYPES = ['rectangle', 'cube', 'sphere', 'disk', 'cylinder', 'obj', 'ply', 'serialized', 'shapegroup', 'instance',
         'diffuse', 'conductor', 'roughconductor', 'dielectric', 'thindielectric', 'roughdielectric', 'plastic',
         'roughplastic', 'twosided', 'normalmap', 'bumpmap', 'blendbsdf', 'mask', 'principled', 'checkerboard',
         'bitmap', 'mesh_attribute', 'area', 'point', 'spot', 'directional', 'constant', 'envmap', 'perspective',
         'thinlens', 'orthographic', 'hdrfilm', 'box', 'gaussian', 'tent', 'mitchell', 'catmullrom', 'lanczos',
         'path', 'sppm', 'independent', 'bogus', '']
NAMES = ['radius', 'fov', 'width', 'height', 'max_depth', 'rr_depth', 'alpha', 'alpha_u', 'alpha_v', 'int_ior',
         'ext_ior', 'eta', 'k', 'reflectance', 'radiance', 'intensity', 'irradiance', 'scale', 'filename',
         'to_world', 'to_uv', 'center', 'p0', 'p1', 'weight', 'opacity', 'stddev', 'lobes', 'B', 'C',
         'cutoff_angle', 'beam_width', 'sample_count', 'aperture_radius', 'focus_distance', 'crop_offset_x',
         'crop_width', 'crop_height', 'shape_index', 'near_clip', 'far_clip', 'fov_axis', 'material',
         'distribution', 'lookat', 'bogus', '']
# Bad command-line values: (option, values). `big` ones may legitimately ask for a long run.
CLI = [('--spp', ['0', '-1', 'abc', '18446744073709551616', '1e3', '']),
       ('--max-depth', ['-2', '0', '4294967296', 'x']),
       ('--threads', ['20000', '-1', '1025', '1.5']),
       ('--seed', ['-1', 'x', '18446744073709551616']),
       ('-D', ['res=0', 'res=-16', 'res=abc', 'res=', '=16', 'res', 'res=100000', 'nonexistent=1', 'res=16=16']),
       ('--integrator', ['bogus', '', 'SPPM']),
       ('--passes', ['0', '3,2', '', '2,,4', '-1', '2,2', 'x']),
       ('--photons', ['0', '-5', '1e13', '10000000000000', '18446744073709551616'])]
BIG_CLI = {'res=100000', '10000000000000', '1e13'}


def _mut_delete(rng, root):
    pm = {c: p for p in root.iter() for c in p}
    if not pm:
        return None
    e = rng.choice(list(pm))
    pm[e].remove(e)
    return 'delete <%s>' % e.tag


def _mut_dup(rng, root):
    pm = {c: p for p in root.iter() for c in p}
    if not pm:
        return None
    e = rng.choice(list(pm))
    p = pm[e]
    p.insert(list(p).index(e) + 1, copy.deepcopy(e))
    return 'duplicate <%s>' % e.tag


def _mut_delattr(rng, root):
    es = [e for e in root.iter() if e.attrib]
    if not es:
        return None
    e = rng.choice(es)
    a = rng.choice(sorted(e.attrib))
    del e.attrib[a]
    return 'delete attribute %s.%s' % (e.tag, a)


def _numeric(rng, v):
    parts = re.split(r'([-+0-9.eE]+)', v)
    nums = [i for i, p in enumerate(parts) if re.fullmatch(r'[-+]?[0-9.]+([eE][-+]?[0-9]+)?', p)]
    if nums and rng.random() < 0.7:
        i = rng.choice(nums)
        parts[i] = rng.choice(['0', '-' + parts[i].lstrip('-+'), '1e30', 'nan', 'inf', '-inf', '1e-30',
                               parts[i] + '0000', '-1'])
        return ''.join(parts)
    return rng.choice(NUMS)


VALUE_KEYS = ('value', 'x', 'y', 'z', 'angle', 'origin', 'target', 'up')


def _mut_value(rng, root):
    es = [e for e in root.iter() if any(k in e.attrib for k in VALUE_KEYS)]
    if not es:
        return None
    e = rng.choice(es)
    k = rng.choice([k for k in VALUE_KEYS if k in e.attrib])
    old = e.attrib[k]
    e.attrib[k] = _numeric(rng, old)
    return 'value %s.%s %r -> %r' % (e.tag, k, old, e.attrib[k])


def _mut_tag(rng, root):
    es = [e for e in root.iter() if e is not root]
    if not es:
        return None
    e = rng.choice(es)
    old, e.tag = e.tag, rng.choice(TAGS)
    return 'tag <%s> -> <%s>' % (old, e.tag)


def _mut_attr(key, choices):
    def mut(rng, root):
        es = [e for e in root.iter() if key in e.attrib]
        if not es:
            return None
        e = rng.choice(es)
        old, e.attrib[key] = e.attrib[key], rng.choice(choices)
        return '%s %r -> %r' % (key, old, e.attrib[key])
    return mut


def _mut_move(rng, root):
    pm = {c: p for p in root.iter() for c in p}
    if not pm:
        return None
    e = rng.choice(list(pm))
    tgt = rng.choice(list(root.iter()))
    if any(x is tgt for x in e.iter()):
        return None
    pm[e].remove(e)
    tgt.append(e)
    return 'move <%s> into <%s>' % (e.tag, tgt.tag)


def _mut_ref(rng, root):
    es = [e for e in root.iter() if 'id' in e.attrib]
    if es and rng.random() < 0.4:
        e = rng.choice(es)
        e.attrib['id'] = rng.choice(['', 'x y', 'dup', es[0].attrib['id']])
        return 'id -> %r' % e.attrib['id']
    tgt = rng.choice(list(root.iter()))
    r = ET.SubElement(tgt, 'ref')
    r.attrib['id'] = rng.choice([x.attrib['id'] for x in es] + ['missing', ''])
    if rng.random() < 0.3:
        r.attrib['name'] = rng.choice(NAMES)
    return 'add <ref id=%r> in <%s>' % (r.attrib['id'], tgt.tag)


def _floats(s):
    return [float(x) for x in re.split(r'[ ,]+', s.strip()) if x]


def _mut_lookat(rng, root):
    es = [e for e in root.iter() if e.tag == 'lookat']
    if not es:
        return None
    e, c = rng.choice(es), rng.random()
    if c < 0.35:
        e.attrib['target'] = e.attrib.get('origin', '0,0,0')
        return 'lookat origin == target'
    if c < 0.7:
        try:
            o, t = _floats(e.attrib.get('origin', '0 0 0')), _floats(e.attrib.get('target', '0 0 1'))
            e.attrib['up'] = ', '.join(repr((t[i] - o[i]) * rng.choice([1, -2])) for i in range(3))
        except (ValueError, IndexError):
            return None
        return 'lookat up parallel to the view'
    e.attrib['up'] = '0, 0, 0'
    return 'lookat up zero'


def _mut_transform(rng, root):
    es = [e for e in root.iter() if e.tag == 'transform']
    if not es:
        return None
    e, c = rng.choice(es), rng.randrange(6)
    op = [('scale', {'value': '0'}), ('matrix', {'value': ' '.join(['0'] * 16)}),
          ('matrix', {'value': '1 2 3 4 2 4 6 8 0 0 1 0 0 0 0 1'}),
          ('matrix', {'value': ' '.join(['1'] * rng.choice([3, 9, 15, 17]))}),
          ('rotate', {'angle': '45'}),
          ('scale', {'x': '1', 'y': '1', 'z': rng.choice(['0', '-1', '1e-30', '1e30', 'nan'])})][c]
    ET.SubElement(e, op[0], op[1])
    return 'transform += <%s %s>' % op


SPECIAL = ('width', 'height', 'max_depth', 'rr_depth', 'radius', 'fov', 'sample_count', 'alpha', 'crop_width',
           'crop_offset_x', 'shape_index')


def _mut_special(rng, root):
    es = [e for e in root.iter() if e.attrib.get('name') in SPECIAL]
    if not es:
        return None
    e = rng.choice(es)
    old = e.attrib.get('value')
    e.attrib['value'] = rng.choice(['0', '-1', '-2', '180', '179.9999', '1e-8', '1', '1000000', '2147483647',
                                    'nan', '360'])
    return 'special %s %r -> %r' % (e.attrib['name'], old, e.attrib['value'])


def _mut_insert(rng, root):
    tgt, tag, attrs = rng.choice(list(root.iter())), rng.choice(TAGS), {}
    if rng.random() < 0.7:
        attrs['name'] = rng.choice(NAMES)
    if rng.random() < 0.7:
        attrs['value'] = rng.choice(NUMS)
    if rng.random() < 0.5:
        attrs['type'] = rng.choice(TYPES)
    if tag == 'include' or rng.random() < 0.1:
        attrs['filename'] = rng.choice(['scene.xml', 'missing.xml', '/dev/null', '/dev/zero', '.', '',
                                        '../scene/scene.xml', '/etc/passwd'])
    ET.SubElement(tgt, tag, attrs)
    return 'insert <%s %s> into <%s>' % (tag, attrs, tgt.tag)


def _nest(rng, data):
    """Deep nesting before `</scene>` (the parser must refuse it, not overflow its stack)."""
    depth = rng.choice([50, 150, 3000, 20000])
    tag = rng.choice(['bsdf', 'a', 'transform', 'shape'])
    open_ = '<bsdf type="twosided">' if tag == 'bsdf' else '<%s>' % tag
    text = (open_ * depth + '</%s>' % tag * depth).encode()
    i = data.rfind(b'</scene>')
    return data[:i] + text + data[i:], 'nest <%s> %d deep' % (tag, depth)


XML_MUTS = [_mut_delete, _mut_dup, _mut_delattr, _mut_value, _mut_value, _mut_value, _mut_tag,
            _mut_attr('type', TYPES), _mut_attr('name', NAMES), _mut_move, _mut_ref, _mut_lookat, _mut_transform,
            _mut_special, _mut_special, _mut_insert]


def _text_mut(rng, data):
    c = rng.randrange(5)
    if c == 0:
        return data[:rng.randrange(len(data))], 'truncate'
    if c == 1:
        b = bytearray(data)
        for _ in range(rng.randint(1, 5)):
            b[rng.randrange(len(b))] = rng.randrange(256)
        return bytes(b), 'byte flips'
    if c == 2:
        i = rng.randrange(len(data))
        junk = rng.choice([b'<', b'>', b'</scene>', b'&amp', b'&#0;', b'\x00', b'<!--', b']]>', b'"', b'<?xml?>',
                           b'<!DOCTYPE x [<!ENTITY a "aaaaaaaaaa">]>', b'\xef\xbb\xbf'])
        return data[:i] + junk + data[i:], 'insert %r' % junk
    if c == 3:
        i, j = sorted((rng.randrange(len(data)), rng.randrange(len(data))))
        return data[:i] + data[j:], 'cut bytes %d..%d' % (i, j)
    return data.replace(b'\n', b'\r\n'), 'CRLF line ends'


def _render_runs(ctx, rng, case_dir, scene, extra):
    runs = [run(ctx, 'render', scene, '--integrator', 'path', '--spp', 4, '--seed', 1,
                '--out', os.path.join(case_dir, 'o.exr'), *extra,
                outputs=[os.path.join(case_dir, 'o*.exr')])]
    if rng.random() < 0.5:
        runs.append(run(ctx, 'render', scene, '--integrator', 'sppm-ml', '--passes', 2, '--photons', 2000,
                        '--out', os.path.join(case_dir, 'b'), *extra,
                        outputs=[os.path.join(case_dir, 'b_p*.exr')]))
    return runs


def _cli_mut(rng, runs):
    """Replaces or adds one command-line option of every run."""
    opt, vals = rng.choice(CLI)
    val = rng.choice(vals)
    for r in runs:
        cmd = r['cmd']
        if opt in cmd and opt != '-D':
            cmd[cmd.index(opt) + 1] = val
        else:
            cmd += [opt, val]
    return opt, val


def make_xml(rng, ctx, case_dir):
    src = rng.choice(ctx['scenes'])
    name = os.path.basename(src)
    sdir = os.path.join(case_dir, name)
    shutil.copytree(src, sdir, copy_function=os.link)
    data = open(os.path.join(src, 'scene.xml'), 'rb').read()
    desc = [name]
    if rng.random() < 0.12:
        data, d = _text_mut(rng, data)
        desc.append(d)
    else:
        root = ET.fromstring(data)
        for _ in range(rng.choice([1, 1, 1, 2, 3])):
            d = rng.choice(XML_MUTS)(rng, root)
            if d:
                desc.append(d)
        data = ET.tostring(root)
        if rng.random() < 0.03:
            data, d = _nest(rng, data)
            desc.append(d)
    scene = os.path.join(sdir, 'case.xml')
    put(scene, data)
    extra = ['-D', 'res=16'] if name != 'crop' and b'name="res"' in data else []
    runs = _render_runs(ctx, rng, case_dir, scene, extra)
    names = ['case.xml'] + [o for o, _ in CLI]
    big = False
    if rng.random() < 0.1:
        opt, val = _cli_mut(rng, runs)
        desc.append('command line %s %s' % (opt, val))
        names.append(repr(val))  # clap quotes the value it refuses
        big = val in BIG_CLI
    return Case(desc, runs, names=names, big=big)


# ---------------------------------------------------------------- meshes

PLY_TYPES = {'char': 'b', 'int8': 'b', 'uchar': 'B', 'uint8': 'B', 'short': 'h', 'int16': 'h', 'ushort': 'H',
             'uint16': 'H', 'int': 'i', 'int32': 'i', 'uint': 'I', 'uint32': 'I', 'float': 'f', 'float32': 'f',
             'double': 'd', 'float64': 'd'}


def _base_mesh(rng):
    """A bumpy grid of triangles and quads with normals, uvs and colours."""
    n = rng.choice([2, 3, 5])
    m = {'V': [], 'F': [], 'N': [], 'UV': [], 'C': []}
    for j in range(n + 1):
        for i in range(n + 1):
            x, y = i / n * 2 - 1, j / n * 2 - 1
            m['V'].append([x, y, 0.1 * math.sin(3 * x)])
            m['N'].append([0.0, 0.0, 1.0])
            m['UV'].append([i / n, j / n])
            m['C'].append([rng.randrange(256) for _ in range(3)])
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i
            if rng.random() < 0.3:
                m['F'].append([a, a + 1, a + n + 2, a + n + 1])
            else:
                m['F'] += [[a, a + 1, a + n + 2], [a, a + n + 2, a + n + 1]]
    return m


def _ply(rng, m, mut):
    fmt = mut.get('format') or rng.choice(['ascii', 'binary_little_endian', 'binary_big_endian'])
    ctype, cnt_t, idx_t = mut.get('ctype', 'float'), mut.get('cnt_t', 'uchar'), mut.get('idx_t', 'int')
    props = [('x', ctype), ('y', ctype), ('z', ctype)]
    if mut.get('normals'):
        props += [('nx', 'float'), ('ny', 'float'), ('nz', 'float')]
    if mut.get('uv'):
        props += [('u', 'float'), ('v', 'float')]
    if mut.get('color'):
        props += [('red', 'uchar'), ('green', 'uchar'), ('blue', 'uchar')]
    if 'props_edit' in mut:
        props = mut['props_edit'](props)
    hdr = ['ply', 'format %s %s' % (fmt, mut.get('version', '1.0')), 'comment fuzz']
    velem = ['element vertex %s' % mut.get('nv_decl', len(m['V']))] + ['property %s %s' % (t, n) for n, t in props]
    felem = ['element face %s' % mut.get('nf_decl', len(m['F'])),
             'property list %s %s %s' % (cnt_t, idx_t, mut.get('fname', 'vertex_indices'))]
    if mut.get('face_attr'):
        felem.append('property float weight')
    for e in ([felem, velem] if mut.get('face_first') else [velem, felem]):
        hdr += e
    if mut.get('extra_elem'):
        hdr += ['element edge 2', 'property int vertex1', 'property int vertex2']
    hdr.append('end_header')
    nl = mut.get('nl', '\n')
    head = (nl.join(hdr) + nl).encode()
    if mut.get('no_end'):
        head = head.replace(b'end_header' + nl.encode(), b'')
    vrows = []
    for k, v in enumerate(m['V']):
        row = []
        for n, t in props:
            if n in ('x', 'y', 'z'):
                val = v['xyz'.index(n)]
            elif n in ('nx', 'ny', 'nz'):
                val = m['N'][k][['nx', 'ny', 'nz'].index(n)]
            elif n in ('u', 'v'):
                val = m['UV'][k]['uv'.index(n)]
            elif n in ('red', 'green', 'blue'):
                val = m['C'][k][['red', 'green', 'blue'].index(n)]
            else:
                val = 0.5
            row.append((val, t))
        vrows.append(row)
    frows = [[(len(f), cnt_t)] + [(i, idx_t) for i in f] + ([(0.5, 'float')] if mut.get('face_attr') else [])
             for f in m['F']]
    if fmt == 'ascii':
        def txt(val, t):
            if PLY_TYPES.get(t, 'f') in 'fd':
                return repr(float(val))
            return str(int(val)) if math.isfinite(val) else str(val)
        ve = ''.join(' '.join(txt(v, t) for v, t in r) + nl for r in vrows)
        fe = ''.join(' '.join(txt(v, t) for v, t in r) + nl for r in frows)
        body = (fe + ve) if mut.get('face_first') else (ve + fe)
        if mut.get('extra_elem'):
            body += '0 1' + nl + '1 2' + nl
        return head + body.encode()
    end = '<' if fmt == 'binary_little_endian' else '>'

    def pack(val, t):
        c = PLY_TYPES.get(t, 'f')
        if c == 'f' and math.isfinite(val) and abs(val) > 3.4028234663852886e38:
            val = math.copysign(math.inf, val)  # what a float32 cast gives
        if c in 'fd':
            return struct.pack(end + c, float(val))
        if not math.isfinite(val):
            return struct.pack(end + c, 0)
        lo, hi = {'b': (-128, 127), 'B': (0, 255), 'h': (-32768, 32767), 'H': (0, 65535), 'i': (-2**31, 2**31 - 1),
                  'I': (0, 2**32 - 1)}[c]
        return struct.pack(end + c, max(lo, min(hi, int(val))))
    ve = b''.join(b''.join(pack(v, t) for v, t in r) for r in vrows)
    fe = b''.join(b''.join(pack(v, t) for v, t in r) for r in frows)
    body = (fe + ve) if mut.get('face_first') else (ve + fe)
    if mut.get('extra_elem'):
        body += struct.pack(end + 'iiii', 0, 1, 1, 2)
    return head + body


OBJ_GARBAGE = ['f', 'f 1', 'f 1 2', 'f 0 1 2', 'f -100 1 2', 'f 1/0/0 2 3', 'f 1// 2// 3//', 'f 1/2/3/4 2 3',
               'f a b c', 'v', 'v 1 2', 'v 1 2 3 4 5 6 7', 'v nan 0 0', 'v inf inf inf', 'vt', 'vt 1', 'vn 0 0 0',
               'vn', 'o', 'g', 's off', 'usemtl x', 'mtllib missing.mtl', 'l 1 2', 'p 1', 'f 1 2 \\', '\x00',
               '\xff\xfe', 'f 99999999999999999999 1 2', 'f 1 2 3 ' + ' '.join(str(i % 4 + 1) for i in range(200)),
               'f 1/1 2/2 3/3', 'f 1/1/1 2 3', 'vp 1 2 3', 'curv 0 1 1 2', 'f 2147483648 1 2',
               'f -2147483649 1 2', '#' * 100000]


def _obj(rng, m, mut):
    lines = ['# fuzz obj'] + ['v ' + ' '.join(repr(float(x)) for x in v) for v in m['V']]
    if mut.get('uv'):
        lines += ['vt %r %r' % tuple(uv) for uv in m['UV']]
    if mut.get('normals'):
        lines += ['vn ' + ' '.join(repr(float(x)) for x in n) for n in m['N']]
    style, nv = mut.get('style', 'plain'), len(m['V'])

    def ref(i):
        s = str(i - nv) if mut.get('negidx') else str(i + 1)
        return {'vt': s + '/' + s, 'vn': s + '//' + s, 'vtn': s + '/' + s + '/' + s}.get(style, s)
    lines += ['f ' + ' '.join(ref(i) for i in f) for f in m['F']]
    for g in mut.get('garbage', []):
        lines.insert(rng.randrange(len(lines) + 1), g)
    return (mut.get('nl', '\n').join(lines) + '\n').encode()


def _mutate_mesh(rng, m, kind):
    mut, desc = {}, []
    for _ in range(rng.choice([0, 1, 1, 1, 2, 3])):
        c, nv = rng.randrange(20), len(m['V'])
        if not m['F'] or not m['V']:
            break
        if c == 0:
            f = rng.choice(m['F'])
            f[rng.randrange(len(f))] = rng.choice([nv, nv + 1, 2**31 - 1, -1, -2**31, 10**12, 2**32 - 1])
            desc.append('index out of range %s' % f)
        elif c == 1:
            v = rng.choice(m['V'])
            v[rng.randrange(3)] = rng.choice([math.nan, math.inf, -math.inf, 1e38, 3.4e38, 1e300])
            desc.append('vertex %s' % v)
        elif c == 2:
            k = rng.randrange(len(m['F']))
            m['F'][k] = m['F'][k][:rng.choice([0, 1, 2])]
            desc.append('short face %s' % m['F'][k])
        elif c == 3:
            k = rng.randrange(len(m['F']))
            m['F'][k] = [rng.randrange(nv) for _ in range(rng.choice([4, 5, 100, 255]))]
            desc.append('%d-gon' % len(m['F'][k]))
        elif c == 4:
            k = rng.randrange(len(m['F']))
            m['F'][k] = [m['F'][k][0] if m['F'][k] else 0] * 3
            desc.append('degenerate face')
        elif c == 5:
            for v in m['V']:
                v[:] = [0.0, 0.0, 0.0]
            desc.append('all vertices at the origin')
        elif c == 6:
            mut['normals'] = True
            bad = rng.choice([[0.0, 0.0, 0.0], [math.nan] * 3, [1e-30, 0.0, 0.0], [0.0, 0.0, -1.0]])
            for n in m['N']:
                n[:] = bad
            desc.append('normals %s' % bad)
        elif c == 7:
            mut['uv'] = True
            bad = rng.choice([[math.nan, 0.0], [1e30, -1e30], [0.0, 0.0]])
            for uv in m['UV']:
                uv[:] = bad
            desc.append('uvs %s' % bad)
        elif c == 8:
            m['F'] = []
            desc.append('no faces')
        elif c == 9:
            m['V'] = m['V'][:rng.randrange(len(m['V']))]
            desc.append('%d vertices left' % len(m['V']))
        elif kind == 'ply' and c == 10:
            mut['nv_decl'] = rng.choice([nv + 1, nv - 1, 0, -1, 2**31, 2**64, 'abc', ''])
            desc.append('vertex count %r' % mut['nv_decl'])
        elif kind == 'ply' and c == 11:
            mut['nf_decl'] = rng.choice([len(m['F']) + 1, len(m['F']) - 1, 0, -1, 2**40, 'x'])
            desc.append('face count %r' % mut['nf_decl'])
        elif kind == 'ply' and c == 12:
            mut['ctype'] = rng.choice(['double', 'uchar', 'int', 'short', 'bogus', 'list uchar float'])
            desc.append('coordinate type %s' % mut['ctype'])
        elif kind == 'ply' and c == 13:
            mut['cnt_t'] = rng.choice(['int', 'char', 'float', 'uint', 'double', 'bogus'])
            mut['idx_t'] = rng.choice(['uchar', 'short', 'uint', 'float', 'double', 'char', 'int'])
            desc.append('face list %s %s' % (mut['cnt_t'], mut['idx_t']))
        elif kind == 'ply' and c == 14:
            e = rng.randrange(5)
            mut['props_edit'], d = [
                (lambda p: [x for x in p if x[0] != 'z'], 'no z'),
                (lambda p: p + [('x', 'float')], 'x twice'),
                (lambda p: [p[1], p[0]] + p[2:], 'y before x'),
                (lambda p: p + [('r', 'uchar'), ('g', 'uchar')], 'partial colour'),
                (lambda p: p + [('foo', 'list uchar float')], 'list vertex property')][e]
            desc.append(d)
        elif kind == 'ply' and c == 15:
            k = rng.randrange(6)
            key, val = [('format', rng.choice(['binary', 'ascii2', ''])), ('version', rng.choice(['2.0', '', 'x'])),
                        ('face_first', True), ('extra_elem', True), ('no_end', True),
                        ('nl', rng.choice(['\r\n', '\r']))][k]
            mut[key] = val
            desc.append('%s %r' % (key, val))
        elif kind == 'ply' and c == 16:
            mut['fname'] = rng.choice(['vertex_index', 'indices', 'foo'])
            desc.append('face list named %s' % mut['fname'])
        elif kind == 'ply' and c == 17:
            mut['color'], mut['face_attr'] = True, rng.random() < 0.5
            desc.append('colours, face attribute %s' % mut['face_attr'])
        elif kind == 'obj' and c in (10, 11):
            mut['style'] = rng.choice(['vt', 'vn', 'vtn'])
            mut['uv'], mut['normals'] = rng.random() < 0.5, rng.random() < 0.5
            desc.append('faces v/%s, uvs %s, normals %s' % (mut['style'], mut['uv'], mut['normals']))
        elif kind == 'obj' and c == 12:
            mut['negidx'] = True
            desc.append('negative indices')
        elif kind == 'obj' and c in (13, 14, 15):
            g = rng.choice(OBJ_GARBAGE)
            mut.setdefault('garbage', []).append(g)
            desc.append('line %r' % g[:40])
        elif kind == 'obj' and c == 16:
            mut['nl'] = rng.choice(['\r\n', '\r'])
            desc.append('line ends %r' % mut['nl'])
    return mut, desc


MESH_SCENE = '''<scene version="3.0.0">
    <sensor type="perspective">
        <float name="fov" value="50"/>
        <transform name="to_world"><lookat origin="0.3, 0.5, 3" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="12"/><integer name="height" value="12"/><rfilter type="box"/></film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="0.3"/></emitter>
    <emitter type="point"><point name="position" x="0" y="2" z="2"/><rgb name="intensity" value="5"/></emitter>
    <shape type="rectangle"><transform name="to_world"><translate z="-1"/></transform></shape>
    <shape type="%(kind)s">
        <string name="filename" value="%(file)s"/>
        %(extra)s
    </shape>
</scene>
'''
EXTRAS = [(0.25, '<emitter type="area"><rgb name="radiance" value="3"/></emitter>'),
          (0.35, '<boolean name="face_normals" value="true"/>'),
          (0.45, '<boolean name="flip_normals" value="true"/>'),
          (0.55, '<bsdf type="dielectric"/>'),
          (0.62, '<bsdf type="normalmap"><texture type="mesh_attribute" name="normalmap"><string name="name" '
                 'value="vertex_normal"/></texture><bsdf type="diffuse"/></bsdf>')]


def make_mesh(rng, ctx, case_dir):
    r, extra = rng.random(), ''
    if r < 0.25:
        src = rng.choice(ctx['meshes'])
        kind = src.rsplit('.', 1)[1]
        data, d = byte_mut(rng, open(src, 'rb').read(), head=400)
        desc = ['%s: %s' % (os.path.relpath(src, ctx['seeds']), d)]
        if kind == 'serialized':
            extra = '<integer name="shape_index" value="%d"/>' % rng.choice([0, 1, 2, -1])
        elif 'vertex-uchar' in src or 'face-ushort' in src:
            attr = 'vertex_color' if 'vertex-uchar' in src else 'face_color'
            extra = ('<bsdf type="diffuse"><texture type="mesh_attribute" name="reflectance"><string name="name" '
                     'value="%s"/><float name="scale" value="0.0039"/></texture></bsdf>' % attr)
    else:
        kind = 'ply' if r < 0.65 else 'obj'
        m = _base_mesh(rng)
        mut, desc = _mutate_mesh(rng, m, kind)
        data = _ply(rng, m, mut) if kind == 'ply' else _obj(rng, m, mut)
        desc.insert(0, 'generated %s' % kind)
        if rng.random() < 0.2:
            data, d = byte_mut(rng, data)
            desc.append(d)
    fname = 'mesh.' + kind
    put(os.path.join(case_dir, fname), data)
    x = rng.random()
    for p, e in EXTRAS:
        if x < p:
            if not (e.startswith('<bsdf') and 'bsdf' in extra):
                extra += e
            break
    scene = os.path.join(case_dir, 'scene.xml')
    put(scene, MESH_SCENE % {'kind': kind, 'file': fname, 'extra': extra})
    return Case(desc, _render_runs(ctx, rng, case_dir, scene, []), names=[fname, 'scene.xml'])
