"""How the generators in this folder write their JSON files (imported by them; no Mitsuba
needed): every number an f32 value written exactly, one list item per line.

An f32 value is written as the shortest decimal of its f64 value (Python's `repr`), which
reads back to the same f32 with any JSON reader that parses f64 to within a few ulps.
"""
import json
import struct


def f32(x):
    """`x` rounded to f32, as the Python float that holds that value exactly."""
    return struct.unpack("<f", struct.pack("<f", float(x)))[0]


def f32s(v):
    """`f32` of each value of `v`."""
    return [f32(x) for x in v]


def write_json(out, fields):
    """`fields` ((key, value) pairs, in order) as a JSON object: one top-level key per line,
    and a list of objects, lists or strings with one item per line."""
    out.write("{\n")
    for i, (key, value) in enumerate(fields):
        end = "," if i + 1 < len(fields) else ""
        if isinstance(value, list) and value and isinstance(value[0], (dict, list, str)):
            out.write(f"  {json.dumps(key)}: [\n")
            for j, item in enumerate(value):
                out.write(f"    {json.dumps(item)}" + ("," if j + 1 < len(value) else "") + "\n")
            out.write(f"  ]{end}\n")
        else:
            out.write(f"  {json.dumps(key)}: {json.dumps(value)}{end}\n")
    out.write("}\n")
