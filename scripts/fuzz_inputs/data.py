"""Bundle EXRs (`bundle_info`, `infer`), TOML configs (`train`, `evaluate`, `datagen render`) and
datasets (`datagen check`, `train`)."""
import copy
import json
import math
import os
import shutil
import struct
import tomllib

from . import Case, put, run, byte_mut
from . import exr

# ---------------------------------------------------------------- bundles

_loaded = {}


def _load(path):
    if path not in _loaded:
        img = exr.read(path)
        a = img['attrs']
        _loaded[path] = (img['channels'], img['width'], img['height'],
                         a['bundleFormat'][1].decode(), a['bundleMeta'][1].decode())
    return _loaded[path]


def _mutate_bundle(rng, ch, w, h, fmt, meta):
    ch = {k: list(v) for k, v in ch.items()}
    m = json.loads(meta)
    kw, desc, metaraw, extra = {}, [], None, []
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        c = rng.randrange(16)
        if c == 0 and ch:
            k = rng.choice(sorted(ch))
            del ch[k]
            desc.append('drop channel %s' % k)
        elif c == 1 and ch:
            k = rng.choice(sorted(ch))
            nk = rng.choice([k.lower(), k.upper(), k.replace('.', '_'), k + 'x', 'A', k.split('.')[0] + '.A', '',
                             'y.R.R'])
            ch[nk] = ch.pop(k)
            desc.append('rename channel %s -> %r' % (k, nk))
        elif c == 2:
            k = rng.choice(['A', 'extra.R', 'y.A', 'z5.R', 'radius.z5', 'variance.z5'])
            ch[k] = [0.0] * (w * h)
            desc.append('extra channel %s' % k)
        elif c == 3 and ch:
            k = rng.choice(sorted(ch))
            v = rng.choice([math.nan, math.inf, -math.inf, -1.0, -1e30, 1e38, 0.0])
            if rng.random() < 0.5:
                i = rng.randrange(w * h)
                ch[k][i] = v
                desc.append('%s at (%d, %d) = %r' % (k, i % w, i // w, v))
            else:
                ch[k] = [v] * (w * h)
                desc.append('%s = %r everywhere' % (k, v))
        elif c == 4 and ch:
            k = rng.choice(sorted(ch))
            kw.setdefault('ptype', {})[k] = rng.choice([0, 1, 3, 7, -1])
            desc.append('pixel type of %s = %d' % (k, kw['ptype'][k]))
        elif c == 5 and ch:
            k = rng.choice(sorted(ch))
            kw.setdefault('sampling', {})[k] = rng.choice([(2, 2), (1, 2), (0, 0), (-1, 1)])
            desc.append('sampling of %s = %s' % (k, kw['sampling'][k]))
        elif c == 6:
            kw['dw'] = rng.choice([(1, 0, w, h - 1), (0, 0, w - 2, h - 1), (0, 0, w - 1, h), (5, 5, 4, 4),
                                   (0, 0, 2**31 - 1, 2**31 - 1), (-2**31, -2**31, 2**31 - 1, 2**31 - 1),
                                   (0, 0, -1, -1), (-10, -10, w - 11, h - 11), (-65536, 32767, w - 1, h - 1),
                                   (4194304, 0, w - 1, h - 1), (0, 0, w - 1, 4194304)])
            desc.append('dataWindow %s' % (kw['dw'],))
        elif c == 7:
            kw['disp'] = rng.choice([(0, 0, w, h), (0, 0, 0, 0), (0, 0, -5, -5), (0, 0, 2**31 - 1, 0)])
            desc.append('displayWindow %s' % (kw['disp'],))
        elif c == 8:
            k = rng.choice(['width', 'height', 'passes', 'seed', 'photons_per_pass', 'seconds', 'integrator',
                            'scene'])
            m[k] = rng.choice([0, -1, w + 1, h - 1, 2**64, 1e300, None, 'x', [], {}, True, 'sppm', 'path', '',
                               1.5, -0.0])
            desc.append('bundleMeta %s = %r' % (k, m[k]))
        elif c == 9 and m:
            k = rng.choice(sorted(m))
            del m[k]
            desc.append('bundleMeta without %s' % k)
        elif c == 10:
            good = json.dumps(m).encode()
            metaraw = rng.choice([b'', b'{', b'null', b'[]', b'"x"', b'{"width":%d}' % w, b'\xff\xfe',
                                  b'{"a":' * 10000, good + b'garbage', good[:-1] + b',"width":1}',
                                  good.replace(b'"seconds": 0.0', b'"seconds": NaN')])
            desc.append('bundleMeta bytes %r' % metaraw[:60])
        elif c == 11:
            fmt = rng.choice(['', 'sppm-ml-bundle/2', 'sppm-ml-bundle/0', 'x', None])
            desc.append('bundleFormat %r' % fmt)
        elif c == 12:
            extra.append(rng.choice([('bundleMeta', 'int', struct.pack('<i', 5)),
                                     ('bundleFormat', 'float', struct.pack('<f', 1)), ('foo', 'string', b'bar'),
                                     ('bundleMeta', 'string', b'{}'),
                                     ('tiles', 'tiledesc', struct.pack('<IIB', 16, 16, 0))]))
            desc.append('extra attribute %s %s' % extra[-1][:2])
        elif c == 13:
            kw['compression'] = rng.choice([1, 2, 4, 5, 6, 7, 8, 9, 10, 200])
            desc.append('compression %d (data not compressed)' % kw['compression'])
        elif c == 14:
            kw['version'] = rng.choice([1, 2 | 0x200, 2 | 0x400, 2 | 0x800, 2 | 0x1000, 3, 0])
            desc.append('version field 0x%x' % kw['version'])
        elif c == 15:
            i = rng.randrange(5)
            kw['offset_mut'] = [lambda o: [0] * len(o), lambda o: [x + 3 for x in o], lambda o: o[::-1],
                                lambda o: [2**63] + o[1:], lambda o: o[:-1] + [o[-1] + 10**9]][i]
            desc.append('offset table %s' % ['zeros', '+3', 'reversed', '2^63 first', 'last beyond the end'][i])
    if rng.random() < 0.3:
        kw['zip_'] = True
    if rng.random() < 0.1:
        kw['sort'] = False
        desc.append('channels unsorted')
    attrs = [] if fmt is None else [('bundleFormat', 'string', fmt.encode())]
    if rng.random() < 0.05:
        desc.append('no bundleMeta')
    else:
        attrs.append(('bundleMeta', 'string', metaraw if metaraw is not None else json.dumps(m).encode()))
    return ch, attrs + extra, kw, desc


def make_bundle(rng, ctx, case_dir):
    src = rng.choice(ctx['bundles'])
    case = os.path.join(case_dir, 'case.exr')
    desc = [os.path.relpath(src, ctx['seeds'])]
    if rng.random() < 0.4:
        data, d = byte_mut(rng, open(src, 'rb').read(), head=1500)
        put(case, data)
        desc.append(d)
    else:
        ch, w, h, fmt, meta = _load(src)
        ch, attrs, kw, d = _mutate_bundle(rng, ch, w, h, fmt, meta)
        exr.write(case, ch, w, h, attrs, **kw)
        desc += d
        if rng.random() < 0.1:
            data, d = byte_mut(rng, open(case, 'rb').read(), head=1500)
            put(case, data)
            desc.append(d)
    info = run(ctx, 'bundle_info', case)
    if rng.random() < 0.2:
        info['cmd'] += ['--png', os.path.join(case_dir, 'preview')]
    out = os.path.join(case_dir, 'ours.exr')
    inf = run(ctx, 'infer', '--model', ctx['model'], '--input', case, '--output', out, outputs=[out])
    if rng.random() < 0.3:
        ref = os.path.join(case_dir, 'reference.exr')
        shutil.copyfile(ctx['reference'], ref)
        inf['cmd'] += ['--reference', ref]
    return Case(desc, [info, inf], names=['case.exr'])


# ---------------------------------------------------------------- TOML configs


def _tval(v):
    if isinstance(v, bool):
        return 'true' if v else 'false'
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return 'nan' if math.isnan(v) else ('inf' if v > 0 else '-inf') if math.isinf(v) else repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return '[' + ', '.join(_tval(x) for x in v) + ']'
    return '{' + ', '.join('%s = %s' % (json.dumps(k), _tval(x)) for k, x in v.items()) + '}'


def _key(k):
    return k if k and k.replace('_', '').replace('-', '').isalnum() else json.dumps(k)


def dump_toml(d, prefix=''):
    out, tables = [], []
    for k, v in d.items():
        if (isinstance(v, dict) and v) or (isinstance(v, list) and v and all(isinstance(x, dict) for x in v)):
            tables.append((k, v))
        else:
            out.append('%s = %s' % (_key(k), _tval(v)))
    for k, v in tables:
        name = (prefix + '.' if prefix else '') + _key(k)
        for item in (v if isinstance(v, list) else [v]):
            out += ['[[%s]]' % name if isinstance(v, list) else '[%s]' % name, dump_toml(item, name)]
    return '\n'.join(out)


def _weird(ctx):
    return [0, -1, 1, 2**63 - 1, -2**63, 2**31, 10**9, 0.0, -0.5, 1e-300, 1e300, math.nan, math.inf, -math.inf,
            '', 'x', '/nonexistent/dir', '/dev/null', os.path.join(ctx['dataset'], 'manifest.json'), True, [], [0],
            [-1], [3, 2], [1, 1], [2**40], {}, {'a': 1}, [1.5], ['a'], 1.5, 65536, 100000]


def _extra(ctx, kind):
    repo, ds, model = ctx['repo'], ctx['dataset'], ctx['model']
    return {
        'train': {'references': ['/nonexistent', '', os.path.join(ds, 'references'), 1],
                  'train_split': ['test', 'bogus', '', 'val'], 'val_split': ['train', 'bogus', '', 'test'],
                  'val_splt': ['val'], 'weighting': ['relu', 'softmax', 'bogus', 1],
                  'window': [0, 1, 2, 3, 11, 100, 10**6, -1],
                  'levels': [[], [0], [1, 2], [5], [9], [0, 0], [4, 3, 2, 1, 0], [0, 1, 2, 3, 4, 5]],
                  'lr_end': [0.0, -1.0, math.nan, 1.0, 1e-9], 'loss': ['relmse', 'relative_log_l1', 'bogus', 'RelMSE'],
                  'init': ['/nonexistent', model, os.path.join(model, 'model.json'), '/dev/null', ds],
                  'cache_images': [0, 1, 2**63 - 1, -1], 'preset': ['paper', 'small', 'medium', 'tiny', 'bogus', ''],
                  'backend': ['ndarray', 'wgpu', 'bogus', 'flex'], 'patch': [1, 2, 7, 33, 64, 1000, 10**9],
                  'stride': [1, 3, 1000, 10**9], 'batch': [1, 10**6, 10**12]},
        'eval': {'engine': ['native', 'burn', 'bogus'], 'max_depth': [0, 1, 10**9, -1], 'limit': [0, 1, 10**6],
                 'tile': [0, 1, 3, 10**6], 'threads': [0, 1, 1000, 1025, 100000],
                 'backend': ['ndarray', 'bogus', 'wgpu', ''], 'passes': [[], [0], [4, 2], [2, 2], [1], [2**31]],
                 'photons_per_pass': [0, 1, 10**12, 10**13],
                 'scenes': [[{'xml': '/nonexistent.xml'}], [{'xml': os.path.join(repo, 'scenes/default/scene.xml')}],
                            [{}], []],
                 'ablation': [{}, {'x': 1}], 'model': ['/nonexistent', ds, os.path.join(model, 'model.json'), '']},
        'datagen': {'width': [0, 1, 2, 3, 65536], 'height': [0, 1, 7], 'seed': [0, 2**64 - 1],
                    'name': ['', '../x', 'a/b']},
    }[kind]


def _is_big(v):
    if isinstance(v, bool):
        return False
    if isinstance(v, (int, float)):
        return not math.isfinite(v) or abs(v) >= 1000
    if isinstance(v, list):
        return any(_is_big(x) for x in v)
    return isinstance(v, dict) and any(_is_big(x) for x in v.values())


def _mutate_toml(rng, ctx, d, kind):
    d, desc, big = copy.deepcopy(d), [], False
    for _ in range(rng.choice([1, 1, 1, 2, 3])):
        paths = []

        def walk(x, p):
            if isinstance(x, dict):
                for k, v in x.items():
                    paths.append(p + [k])
                    walk(v, p + [k])
            elif isinstance(x, list):
                for i, v in enumerate(x):
                    if isinstance(v, dict):
                        walk(v, p + [i])
        walk(d, [])
        c = rng.randrange(6)
        if c in (0, 1, 2) and paths:
            p = rng.choice(paths)
            parent = d
            for k in p[:-1]:
                parent = parent[k]
            old = parent[p[-1]]
            if c == 0:
                del parent[p[-1]]
                desc.append('delete %s' % '.'.join(map(str, p)))
                continue
            if isinstance(old, list) and old and isinstance(old[0], (int, float)) and rng.random() < 0.5:
                new = rng.choice([[], old[::-1] if len(old) > 1 else old * 2, old[:1], [-old[0]], old + old,
                                  [math.nan, 1.0], [old[0], 1e300]])
            else:
                new = rng.choice(_weird(ctx))
            parent[p[-1]] = new
            big |= _is_big(new)
            desc.append('set %s = %r (was %r)' % ('.'.join(map(str, p)), new,
                                                  '{..}' if isinstance(old, dict) else old))
        elif c == 4:
            k = rng.choice(['bogus', 'Epochs', 'lr ', 'dataset2'])
            d[k] = 1
            desc.append('unknown key %r' % k)
        else:
            ex = _extra(ctx, kind)
            k = rng.choice(sorted(ex))
            d[k] = rng.choice(ex[k])
            big |= _is_big(d[k])
            desc.append('set %s = %r' % (k, d[k]))
    return d, desc, big


def toml_bases(ctx, case_dir):
    repo = ctx['repo']
    load = lambda p: tomllib.load(open(os.path.join(repo, p), 'rb'))
    train = load('configs/train/tiny.toml')
    train.update(dataset=ctx['dataset'], output=os.path.join(case_dir, 'run'))
    ev = load('configs/eval/tiny.toml')
    ev.update(model=ctx['model'], output=os.path.join(case_dir, 'run'), photons_per_pass=1000, passes=[2, 4])
    ev['dataset'].update(dir=ctx['dataset'], limit=1)
    return {'train': train, 'eval': ev, 'datagen': load('configs/datagen/tiny.toml')}


def make_toml(rng, ctx, case_dir):
    kind = rng.choice(['train', 'eval', 'datagen'])
    d, desc, big = _mutate_toml(rng, ctx, toml_bases(ctx, case_dir)[kind], kind)
    text = dump_toml(d)
    if rng.random() < 0.08:
        text = text[:rng.randrange(len(text) + 1)]
        desc.append('truncated')
    cfg = os.path.join(case_dir, 'case.toml')
    put(cfg, text + '\n')
    out = os.path.join(case_dir, 'run')
    r = {'train': lambda: run(ctx, 'train', '--config', cfg),
         'eval': lambda: run(ctx, 'evaluate', '--config', cfg),
         'datagen': lambda: run(ctx, 'datagen', 'render', '--config', cfg, '--out', out, outputs=[out])}[kind]()
    keys = [k for k in _extra(ctx, kind)] + ['bogus', 'Epochs', 'lr ', 'dataset2']
    return Case([kind] + desc, [r], names=['case.toml'] + keys, big=big)


# ---------------------------------------------------------------- datasets


def make_dataset(rng, ctx, case_dir):
    ds = os.path.join(case_dir, 'dataset')
    shutil.copytree(ctx['dataset'], ds)
    m = json.load(open(os.path.join(ds, 'manifest.json')))
    weird = [None, 0, -1, 2**64, 1e300, '', 'x', '../../etc/passwd', '/dev/null', [], {}, True,
             'references/001-glass.exr', 'bundles/000-room/s00_p00002.exr']
    desc, touched = [], ['manifest.json']

    def files(pred=lambda f: True):
        return sorted(os.path.join(dp, f) for dp, _, fl in os.walk(ds) for f in fl
                      if f != 'manifest.json' and pred(f))
    for _ in range(rng.choice([1, 1, 2])):
        c = rng.randrange(8)
        scenes = m.get('scenes')
        if c in (1, 2, 3) and not (isinstance(scenes, list) and scenes and
                                   all(isinstance(x, dict) and x for x in scenes)):
            c = 4
        if c == 0:
            k = rng.choice(sorted(m))
            m[k] = rng.choice(weird)
            desc.append('manifest %s = %r' % (k, m[k]))
        elif c == 1:
            i = rng.randrange(len(scenes))
            k = rng.choice(sorted(scenes[i]))
            scenes[i][k] = rng.choice(weird)
            desc.append('manifest scenes[%d].%s = %r' % (i, k, scenes[i][k]))
        elif c == 2:
            i = rng.randrange(len(scenes))
            k = rng.choice(sorted(scenes[i]))
            del scenes[i][k]
            desc.append('manifest scenes[%d] without %s' % (i, k))
        elif c == 3:
            scenes.append(copy.deepcopy(rng.choice(scenes)))
            desc.append('manifest scene listed twice')
        else:
            f = rng.choice(files(lambda f: c != 5 or f.endswith(('.exr', '.json'))))
            rel = os.path.relpath(f, ds)
            touched.append(os.path.basename(f))
            data = open(f, 'rb').read()
            if c == 4:
                os.remove(f)
                desc.append('delete %s' % rel)
            elif c == 5:
                put(f, data[:rng.randrange(len(data))])
                desc.append('truncate %s' % rel)
            else:
                data, d = byte_mut(rng, data)
                put(f, data)
                desc.append('%s: %s' % (rel, d))
    put(os.path.join(ds, 'manifest.json'), json.dumps(m, indent=2))
    train = toml_bases(ctx, case_dir)['train']
    train.update(dataset=ds)
    cfg = os.path.join(case_dir, 'train.toml')
    put(cfg, dump_toml(train) + '\n')
    return Case(desc, [run(ctx, 'datagen', 'check', '--quiet', ds), run(ctx, 'train', '--config', cfg)],
                names=touched + [ds, 'BAD '])  # `datagen check` lines: `BAD <file>: <problem>`
