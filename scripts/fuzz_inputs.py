#!/usr/bin/env python3
"""Feed the release binaries mutated inputs and check that each one ends in a clear error or a
sane result: never a panic, a crash (abort, signal), a hang or a non-finite output.

    python3 scripts/fuzz_inputs.py [--bin-dir target/release] [--only xml,mesh,bundle,toml,dataset]
                                   [--cases N] [--seed S] [--jobs J] [--out DIR]

Kinds (what is mutated -> what runs):
  xml      the repository's scenes and a generated dataset's scenes -> render (path; sppm-ml for half),
           a tenth with one bad command-line value
  mesh     generated PLY/OBJ and byte-mutated repository meshes     -> render (path; sppm-ml for half)
  bundle   bundle EXRs (header, channels, metadata, bytes)           -> bundle_info, infer
  toml     train / evaluate / datagen configs                        -> train, evaluate, datagen render
  dataset  a generated tiny dataset (manifest edits, deleted, truncated, corrupted files)
                                                                     -> datagen check, train
Every run is classified (first match): `timeout` (`slow` when the case asked for a large amount of
work), `panic` ("panicked" in the output or exit 101), `crash` (a signal, or exit 134/136/137/139),
then on exit 0 `nonfinite` (an output EXR holds NaN/inf), `no-output` (the promised output file is
missing) or `accepted`, and on exit 1/2 `error` when the first error line names the input file (or
the option/key) and `vague-error` otherwise (other exit codes: `vague-error` too). Exit status 1
when any panic, crash, timeout, nonfinite or no-output run is found; the reproducing case
(input files, `repro.sh`, `info.json`) is kept under <out>/findings/. The same seed gives the same
cases, for any --jobs. Standard library only; the binaries must be built first:
    cargo build --release --locked -p renderer -p datagen -p train -p infer
"""
import argparse
import glob
import json
import os
import random
import re
import shlex
import shutil
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from fuzz_inputs import exr, scenes, data  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
KINDS = {'xml': scenes.make_xml, 'mesh': scenes.make_mesh, 'bundle': data.make_bundle,
         'toml': data.make_toml, 'dataset': data.make_dataset}
BINS = {'xml': ['render'], 'mesh': ['render'], 'bundle': ['bundle_info', 'infer'],
        'toml': ['train', 'evaluate', 'datagen'], 'dataset': ['datagen', 'train']}
FAIL = ('panic', 'crash', 'timeout', 'nonfinite', 'no-output')
CLASSES = ('error', 'vague-error', 'accepted', 'slow') + FAIL
ENV = dict(os.environ, RUST_BACKTRACE='0', RUST_LIB_BACKTRACE='0')


def execute(cmd, cwd, timeout, mem_kb):
    """(rc or 'timeout', stdout, stderr, seconds) of one capped run."""
    t0 = time.time()
    p = subprocess.Popen(['bash', '-c', 'ulimit -v %d; exec "$@"' % mem_kb, 'fuzz'] + cmd, cwd=cwd, env=ENV,
                         stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout)
        rc = p.returncode
    except subprocess.TimeoutExpired:
        try:
            os.killpg(p.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        out, err = p.communicate()
        rc = 'timeout'
    return rc, out.decode('utf-8', 'replace'), err.decode('utf-8', 'replace'), time.time() - t0


def message_line(out, err):
    """The line a user reads: the first that says `error` (or `BAD`, as `datagen check` does) on
    stderr, then stdout; else the last line of stderr (or stdout) but Rust's `note: ...`."""
    for text in (err, out):
        for l in text.splitlines():
            if 'error' in l.lower() or l.startswith('BAD '):
                return l.strip()
    lines = [l.strip() for l in (err or out).splitlines() if l.strip() and not l.startswith('note: ')]
    return lines[-1] if lines else ''


def check_outputs(ctx, patterns):
    """None if every promised output exists and is finite, else (class, detail)."""
    for pat in patterns:
        found = sorted(glob.glob(pat)) if '*' in pat else ([pat] if os.path.exists(pat) else [])
        if not found:
            return 'no-output', 'exit 0 but no %s' % os.path.basename(pat)
        files = []
        for f in found:
            files += sorted(glob.glob(os.path.join(f, '**', '*.exr'), recursive=True)) if os.path.isdir(f) else [f]
        for f in files[:40]:
            try:
                bad = exr.first_non_finite(f)
            except Exception:  # a layout this reader lacks: ask the toolkit, or leave it unchecked
                bad = None
                ctx['unchecked'] += 1
                if 'bundle_info' in ctx['bins']:
                    rc, o, _, _ = execute([ctx['bins']['bundle_info'], f], ctx['repo'], 30, ctx['mem_kb'])
                    m = re.search(r'first non-finite sample: (.*)', o)
                    bad = m.group(1) if rc == 0 and m else None
            if bad:
                return 'nonfinite', '%s: %s' % (os.path.basename(f), bad)
    return None


def classify(ctx, case, r, rc, out, err):
    text = out + err
    if rc == 'timeout':
        return ('slow' if case.big else 'timeout'), 'no exit after %g s' % ctx['timeout']
    if 'panicked' in text or rc == 101:
        m = re.search(r"panicked at ([^\n]*)\n?([^\n]*)", text)
        return 'panic', ('%s %s' % m.groups()).strip() if m else 'exit 101'
    if rc < 0 or rc in (134, 136, 137, 139):
        what = 'signal %d' % -rc if rc < 0 else 'exit %d' % rc
        return 'crash', '%s: %s' % (what, message_line(out, err)[:300])
    if rc == 0:
        return check_outputs(ctx, r['outputs']) or ('accepted', '')
    line = message_line(out, err)
    named = rc in (1, 2) and any(n and n in line for n in case.names)
    return ('error' if named else 'vague-error'), 'exit %d: %s' % (rc, line[:300])


def dedup_key(binary, cls, detail):
    loc = re.match(r'(\S+:\d+)', detail) if cls == 'panic' else None
    return '%s | %s | %s' % (binary, cls, loc.group(1) if loc else re.sub(r'\d+', 'N', detail)[:80])


def run_case(ctx, kind, i):
    case_dir = os.path.join(ctx['work'], '%s-%05d' % (kind, i))
    shutil.rmtree(case_dir, ignore_errors=True)
    os.makedirs(case_dir)
    rng = random.Random('%d:%s:%d' % (ctx['seed'], kind, i))
    try:
        case = KINDS[kind](rng, ctx, case_dir)
    except Exception as e:  # a bug of this script, not of the binaries
        shutil.rmtree(case_dir, ignore_errors=True)
        return {'kind': kind, 'case': i, 'generator_error': '%s: %s' % (type(e).__name__, e), 'runs': []}
    res = {'kind': kind, 'case': i, 'dir': case_dir, 'desc': case.desc, 'runs': []}
    for r in case.runs:
        rc, out, err, dt = execute(r['cmd'], case_dir, ctx['timeout'], ctx['mem_kb'])
        cls, detail = classify(ctx, case, r, rc, out, err)
        res['runs'].append({'binary': os.path.basename(r['cmd'][0]), 'cmd': r['cmd'], 'rc': rc, 'class': cls,
                            'detail': detail, 'seconds': round(dt, 3), 'stdout': out[-3000:],
                            'stderr': err[-5000:]})
    return res


def save_finding(ctx, res):
    dst = os.path.join(ctx['out'], 'findings', os.path.basename(res['dir']))
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(res['dir'], dst, ignore=shutil.ignore_patterns('run', 'o*.exr', 'b_p*.exr', 'ours.exr',
                                                                   'preview_*.png'))
    lines = ['#!/bin/sh', '# %s case %d: %s' % (res['kind'], res['case'], '; '.join(res['desc'])),
             'D=$(cd "$(dirname "$0")" && pwd)', 'cd "$D"', 'ulimit -v %d' % ctx['mem_kb']]
    for r in res['runs']:
        if r['class'] in FAIL:
            lines.append('# %s: %s' % (r['class'], r['detail'][:200]))
            lines.append(' '.join(shlex.quote(a) for a in r['cmd']).replace(res['dir'], '"$D"'))
    with open(os.path.join(dst, 'repro.sh'), 'w') as f:
        f.write('\n'.join(lines) + '\n')
    os.chmod(os.path.join(dst, 'repro.sh'), 0o755)
    for name in ('case.xml', 'case.toml', 'train.toml', 'scene.xml'):  # point paths at the kept copy
        for p in glob.glob(os.path.join(dst, '**', name), recursive=True):
            text = open(p, 'rb').read().replace(res['dir'].encode(), dst.encode())
            open(p, 'wb').write(text)
    with open(os.path.join(dst, 'info.json'), 'w') as f:
        json.dump({k: res[k] for k in ('kind', 'case', 'desc', 'runs')}, f, indent=1)
    return os.path.relpath(dst, REPO) if dst.startswith(REPO) else dst


def setup_seeds(ctx, kinds):
    """Seed inputs: the repository's scenes and a `tiny` dataset generated by `datagen`."""
    seeds = ctx['seeds']
    shutil.rmtree(seeds, ignore_errors=True)
    os.makedirs(os.path.join(seeds, 'scenes'))
    for src in [os.path.join(REPO, 'scenes/default')] + sorted(glob.glob(os.path.join(REPO, 'scenes/validation/*'))):
        if os.path.isfile(os.path.join(src, 'scene.xml')):
            shutil.copytree(src, os.path.join(seeds, 'scenes', os.path.basename(src)))
    ctx['dataset'] = os.path.join(seeds, 'tiny')
    if set(kinds) - {'mesh'} and 'datagen' in ctx['bins']:
        cmd = [ctx['bins']['datagen'], 'render', '--config', os.path.join(REPO, 'configs/datagen/tiny.toml'),
               '--out', ctx['dataset']]
        rc, out, err, _ = execute(cmd, seeds, 600, ctx['mem_kb'])
        if rc != 0:
            sys.exit('generating the seed dataset failed (%s): %s' % (' '.join(cmd), (err or out)[-2000:]))
        for s in sorted(glob.glob(os.path.join(ctx['dataset'], 'scenes', '*'))):
            shutil.copytree(s, os.path.join(seeds, 'scenes', os.path.basename(s)))
    ctx['scenes'] = sorted(glob.glob(os.path.join(seeds, 'scenes', '*')))
    ctx['meshes'] = sorted(p for ext in ('ply', 'obj', 'serialized')
                           for p in glob.glob(os.path.join(seeds, 'scenes', '**', '*.' + ext), recursive=True))
    ctx['bundles'] = sorted(glob.glob(os.path.join(ctx['dataset'], 'bundles', '*', '*.exr')))
    ctx['reference'] = os.path.join(ctx['dataset'], 'references', '000-room.exr')


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__[__doc__.index('Kinds'):])
    ap.add_argument('--bin-dir', default='target/release', help='directory of the release binaries')
    ap.add_argument('--only', default=','.join(KINDS), help='comma-separated kinds (default: all)')
    ap.add_argument('--cases', type=int, default=200, help='cases per kind (default 200)')
    ap.add_argument('--seed', type=int, default=1)
    ap.add_argument('--jobs', type=int, default=1, help='cases run in parallel (default 1)')
    ap.add_argument('--out', help='output directory (default out/fuzz/inputs-<seed>)')
    ap.add_argument('--timeout', type=float, default=20, help='seconds per run (default 20)')
    ap.add_argument('--mem-mb', type=int, default=6000, help='address-space cap per run, MiB (default 6000)')
    ap.add_argument('--keep-work', action='store_true', help='keep every case directory (<out>/work)')
    ap.add_argument('--repro-per-key', type=int, default=3, help='cases kept per distinct finding (default 3)')
    a = ap.parse_args()
    kinds = [k.strip() for k in a.only.split(',') if k.strip()]
    if not kinds or any(k not in KINDS for k in kinds):
        ap.error('--only takes a comma-separated subset of %s' % ','.join(KINDS))
    bin_dir = os.path.abspath(os.path.join(REPO, a.bin_dir) if not os.path.isabs(a.bin_dir) else a.bin_dir)
    need = sorted({b for k in kinds for b in BINS[k]} | ({'datagen'} if set(kinds) - {'mesh'} else set()))
    missing = [b for b in need if not os.access(os.path.join(bin_dir, b), os.X_OK)]
    if missing:
        sys.exit('missing binaries in %s: %s (cargo build --release --locked -p renderer -p datagen -p train '
                 '-p infer)' % (bin_dir, ', '.join(missing)))
    out = os.path.abspath(a.out or os.path.join(REPO, 'out', 'fuzz', 'inputs-%d' % a.seed))
    shutil.rmtree(os.path.join(out, 'findings'), ignore_errors=True)
    ctx = {'bin': bin_dir, 'bins': {b: os.path.join(bin_dir, b) for b in os.listdir(bin_dir)}, 'repo': REPO,
           'model': os.path.join(REPO, 'models', 'default'), 'seed': a.seed, 'timeout': a.timeout,
           'mem_kb': a.mem_mb * 1024, 'out': out, 'work': os.path.join(out, 'work'),
           'seeds': os.path.join(out, 'seeds'), 'unchecked': 0}
    t_start = time.time()
    setup_seeds(ctx, kinds)
    report = {'command': ' '.join(shlex.quote(x) for x in sys.argv), 'seed': a.seed, 'cases_per_kind': a.cases,
              'bin_dir': bin_dir, 'timeout_s': a.timeout, 'mem_mb': a.mem_mb, 'kinds': {}, 'findings': [],
              'vague_errors': [], 'accepted': [], 'slow': [], 'generator_errors': []}
    seen, rows = {}, []
    for kind in kinds:
        t0, counts, nruns = time.time(), {c: 0 for c in CLASSES}, 0
        with ThreadPoolExecutor(max(1, a.jobs)) as pool:
            for res in pool.map(lambda i: run_case(ctx, kind, i), range(a.cases)):
                if 'generator_error' in res:
                    report['generator_errors'].append(res)
                    continue
                keep = False
                for r in res['runs']:
                    nruns += 1
                    counts[r['class']] += 1
                    entry = {'kind': kind, 'case': res['case'], 'binary': r['binary'], 'class': r['class'],
                             'detail': r['detail'], 'desc': res['desc']}
                    if r['class'] in FAIL:
                        key = dedup_key(r['binary'], r['class'], r['detail'])
                        seen[key] = seen.get(key, 0) + 1
                        entry['key'] = key
                        keep |= seen[key] <= a.repro_per_key
                        report['findings'].append(entry)
                        print('[%s %d] %s %s: %s | %s' % (kind, res['case'], r['binary'], r['class'],
                                                          r['detail'][:160], '; '.join(res['desc'])[:200]), flush=True)
                    elif r['class'] == 'vague-error':
                        report['vague_errors'].append(entry)
                    elif r['class'] in ('accepted', 'slow'):
                        report[r['class']].append(entry)
                if keep:
                    path = save_finding(ctx, res)
                    for e in report['findings']:
                        if e['kind'] == kind and e['case'] == res['case']:
                            e['repro'] = path
                if not a.keep_work:
                    shutil.rmtree(res['dir'], ignore_errors=True)
        dt = time.time() - t0
        report['kinds'][kind] = {'cases': a.cases, 'runs': nruns, 'seconds': round(dt, 1), 'classes': counts}
        rows.append([kind, a.cases, nruns] + [counts[c] for c in CLASSES] + ['%.0f' % dt])
    report['seconds'] = round(time.time() - t_start, 1)
    report['distinct_findings'] = seen
    report['outputs_not_checked'] = ctx['unchecked']
    failed = any(report['kinds'][k]['classes'][c] for k in kinds for c in FAIL)
    report['result'] = 'FAIL' if failed else 'PASS'
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, 'report.json'), 'w') as f:
        json.dump(report, f, indent=1)
    if not a.keep_work:
        shutil.rmtree(ctx['work'], ignore_errors=True)
        if not report['findings']:
            shutil.rmtree(ctx['seeds'], ignore_errors=True)  # findings' repro.sh may point into it
    head = ['kind', 'cases', 'runs'] + list(CLASSES) + ['s']
    widths = [max(len(str(x)) for x in col) for col in zip(head, *rows)]
    print()
    for row in [head] + rows:
        print('  '.join(str(x).rjust(w) for x, w in zip(row, widths)))
    print('\n%s in %.0f s; distinct findings: %d; report: %s' % (report['result'], report['seconds'], len(seen),
                                                                 os.path.join(out, 'report.json')))
    for key, n in sorted(seen.items()):
        print('  %4d  %s' % (n, key))
    if report['generator_errors']:
        print('warning: %d cases could not be generated (a bug of this script): %s' % (
            len(report['generator_errors']), report['generator_errors'][0]['generator_error']))
    sys.exit(1 if failed else 0)


if __name__ == '__main__':
    main()
