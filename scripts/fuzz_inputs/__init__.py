"""Case generators for scripts/fuzz_inputs.py: one module per input family.

Each generator is `make(rng, ctx, case_dir) -> Case | None`: it writes one mutated input
(and whatever it needs beside it) into `case_dir` and says which binaries to run on it.
"""
import os
from dataclasses import dataclass, field


@dataclass
class Case:
    desc: list                                  # the mutations, in words
    runs: list = field(default_factory=list)    # [{'cmd': [...], 'outputs': [paths checked when rc 0]}]
    names: list = field(default_factory=list)   # strings an error message may use to name the input
    big: bool = False                           # asks for legitimately long work: a timeout is `slow`


def run(ctx, binary, *args, outputs=()):
    return {'cmd': [os.path.join(ctx['bin'], binary)] + [str(a) for a in args], 'outputs': list(outputs)}


def put(path, data):
    """Writes a fresh file (never through a hard link into the seed copy)."""
    if os.path.lexists(path):
        os.remove(path)
    with open(path, 'wb' if isinstance(data, bytes) else 'w') as f:
        f.write(data)


def byte_mut(rng, data, head=None):
    """Truncation, byte flips, an int32 poke or inserted junk; `head` biases edits to the
    first bytes (headers)."""
    if not data:
        return bytes(rng.randrange(256) for _ in range(rng.randint(1, 64))), 'random bytes'
    near = (lambda: rng.randrange(min(len(data), head))) if head else (lambda: rng.randrange(len(data)))
    c = rng.randrange(4)
    if c == 0:
        i = rng.choice([rng.randrange(len(data)), near(), max(0, len(data) - rng.randrange(1, 64))])
        return data[:i], 'truncate at %d' % i
    if c == 1:
        b, pos = bytearray(data), []
        for _ in range(rng.randint(1, 6)):
            p = rng.choice([rng.randrange(len(b)), near()])
            b[p] = rng.randrange(256)
            pos.append(p)
        return bytes(b), 'byte flips at %s' % pos
    if c == 2 and len(data) > 4:
        import struct
        b, p = bytearray(data), near()
        v = rng.choice([-1, 2**31 - 1, 0, 2**30, 65536, -65536])
        b[p:p + 4] = struct.pack('<i', v)
        return bytes(b), 'int32 %d at %d' % (v, p)
    i = rng.randrange(len(data) + 1)
    return data[:i] + bytes(rng.randrange(256) for _ in range(rng.randint(1, 32))) + data[i:], 'junk at %d' % i
