"""Minimal OpenEXR reading and writing in the standard library, for fuzzing.

`read` decodes single-part scanline or tiled files with NONE, RLE, ZIPS or ZIP compression
(what the toolkit writes) into per-channel lists; `write` builds uncompressed or ZIP scanline
files with every header field under the caller's control, so headers can be made wrong on
purpose.
"""
import math
import struct
import zlib

PIXEL_SIZE = {0: 4, 1: 2, 2: 4}  # uint, half, float
PIXEL_FMT = {0: 'I', 1: 'e', 2: 'f'}
LINES = {0: 1, 1: 1, 2: 1, 3: 16}  # lines per block for NONE, RLE, ZIPS, ZIP


class ExrError(Exception):
    pass


def _cstr(d, pos):
    end = d.index(b'\0', pos)
    return d[pos:end].decode('latin-1'), end + 1


def read_header(d):
    """(attributes {name: (type, bytes)}, offset just past the header). Single-part only."""
    if len(d) < 8 or struct.unpack('<i', d[:4])[0] != 20000630:
        raise ExrError('not an OpenEXR file')
    flags = struct.unpack('<i', d[4:8])[0]
    if flags & 0x1000 or flags & 0x800:
        raise ExrError('multi-part or deep files are not supported here')
    attrs, pos = {}, 8
    while d[pos] != 0:
        name, pos = _cstr(d, pos)
        typ, pos = _cstr(d, pos)
        size = struct.unpack('<i', d[pos:pos + 4])[0]
        pos += 4
        attrs[name] = (typ, d[pos:pos + size])
        pos += size
    return attrs, pos + 1


def channels_of(raw):
    """[(name, pixel type, xs, ys)] of a `chlist` attribute."""
    out, pos = [], 0
    while raw[pos] != 0:
        name, pos = _cstr(raw, pos)
        pt, _, xs, ys = struct.unpack('<iB3xii', raw[pos:pos + 16])
        pos += 16
        out.append((name, pt, xs, ys))
    return out


def _unpredict(data):
    """Inverse of the ZIP/ZIPS predictor and byte interleave."""
    t = bytearray(data)
    for i in range(1, len(t)):
        t[i] = (t[i - 1] + t[i] - 128) & 0xff
    half = (len(t) + 1) // 2
    out = bytearray(len(t))
    out[0::2], out[1::2] = t[:half], t[half:]
    return bytes(out)


def _unrle(data):
    out, i = bytearray(), 0
    while i < len(data):
        n = struct.unpack('b', data[i:i + 1])[0]
        if n < 0:
            out += data[i + 1:i + 1 - n]
            i += 1 - n
        else:
            out += data[i + 1:i + 2] * (n + 1)
            i += 2
    return _unpredict(bytes(out))


def _decode(comp, data, expected):
    if len(data) == expected:
        return data  # stored uncompressed when compression does not help
    if comp in (2, 3):
        return _unpredict(zlib.decompress(data))
    if comp == 1:
        return _unrle(data)
    raise ExrError('compression %d is not supported here' % comp)


def read(path):
    """{'attrs': header, 'width', 'height', 'channels': {name: [values, row-major]}}."""
    d = open(path, 'rb').read()
    attrs, pos = read_header(d)
    chans = channels_of(attrs['channels'][1])
    comp = attrs['compression'][1][0]
    x0, y0, x1, y1 = struct.unpack('<iiii', attrs['dataWindow'][1])
    w, h = x1 - x0 + 1, y1 - y0 + 1
    if w <= 0 or h <= 0 or w * h > 1 << 26:
        raise ExrError('implausible data window')
    if any(xs != 1 or ys != 1 for _, _, xs, ys in chans):
        raise ExrError('subsampled channels are not supported here')
    values = {n: [0.0] * (w * h) for n, _, _, _ in chans}
    tiled = 'tiles' in attrs
    if tiled:
        tw, th, mode = struct.unpack('<IIB', attrs['tiles'][1])
        if mode & 0xf:
            raise ExrError('mip/rip-mapped files are not supported here')
        nblocks = ((w + tw - 1) // tw) * ((h + th - 1) // th)
    else:
        lines = LINES.get(comp)
        if lines is None:
            raise ExrError('compression %d is not supported here' % comp)
        nblocks = (h + lines - 1) // lines
    offsets = struct.unpack('<%dQ' % nblocks, d[pos:pos + 8 * nblocks])
    for off in offsets:
        if tiled:
            tx, ty, _, _, size = struct.unpack('<iiiii', d[off:off + 20])
            data = d[off + 20:off + 20 + size]
            bx, by = tx * tw, ty * th
            bw, bh = min(tw, w - bx), min(th, h - by)
        else:
            y, size = struct.unpack('<ii', d[off:off + 8])
            data = d[off + 8:off + 8 + size]
            bx, by, bw = 0, y - y0, w
            bh = min(lines, h - by)
        expected = bh * sum(bw * PIXEL_SIZE[pt] for _, pt, _, _ in chans)
        raw = _decode(comp, data, expected)
        if len(raw) != expected:
            raise ExrError('block of %d bytes, expected %d' % (len(raw), expected))
        p = 0
        for row in range(bh):
            for name, pt, _, _ in chans:
                n = bw * PIXEL_SIZE[pt]
                vals = struct.unpack('<%d%s' % (bw, PIXEL_FMT[pt]), raw[p:p + n])
                p += n
                start = (by + row) * w + bx
                values[name][start:start + bw] = vals
    return {'attrs': attrs, 'width': w, 'height': h, 'channels': values}


def first_non_finite(path):
    """None when every float/half sample of the file is finite, else 'channel at (x, y) = v'."""
    img = read(path)
    w = img['width']
    for name, vals in img['channels'].items():
        for i, v in enumerate(vals):
            if isinstance(v, float) and not math.isfinite(v):
                return '%s at (%d, %d) = %r (%d non-finite)' % (
                    name, i % w, i // w, v, sum(1 for x in vals if isinstance(x, float) and not math.isfinite(x)))
    return None


def attr(name, typ, data):
    return name.encode() + b'\0' + typ.encode() + b'\0' + struct.pack('<i', len(data)) + data


def write(path, channels, width, height, attrs=(), ptype=None, dw=None, disp=None, compression=0,
          version=2, sort=True, offset_mut=None, sampling=None, zip_=False):
    """Scanline EXR. channels: {name: row-major list of width*height values}; attrs: extra
    (name, type, bytes) header attributes. Every other argument overrides one header field."""
    names = sorted(channels) if sort else list(channels)
    ptype, sampling = ptype or {}, sampling or {}
    chs = [(n, ptype.get(n, 2)) + tuple(sampling.get(n, (1, 1))) for n in names]
    chl = b''.join(n.encode() + b'\0' + struct.pack('<iB3xii', pt, 0, xs, ys) for n, pt, xs, ys in chs) + b'\0'
    dw = dw or (0, 0, width - 1, height - 1)
    hdr = struct.pack('<ii', 20000630, version)
    hdr += attr('channels', 'chlist', chl)
    hdr += attr('compression', 'compression', bytes([3 if zip_ else compression]))
    hdr += attr('dataWindow', 'box2i', struct.pack('<iiii', *dw))
    hdr += attr('displayWindow', 'box2i', struct.pack('<iiii', *(disp or dw)))
    hdr += attr('lineOrder', 'lineOrder', b'\0')
    hdr += attr('pixelAspectRatio', 'float', struct.pack('<f', 1.0))
    hdr += attr('screenWindowCenter', 'v2f', struct.pack('<ff', 0, 0))
    hdr += attr('screenWindowWidth', 'float', struct.pack('<f', 1.0))
    for a in attrs:
        hdr += attr(*a)
    hdr += b'\0'
    lines = 16 if zip_ else 1
    blocks = []
    for b in range(0, height, lines):
        data = bytearray()
        for y in range(b, min(height, b + lines)):
            for n, pt, _, _ in chs:
                row = channels[n][y * width:(y + 1) * width]
                if pt == 1:
                    row = [max(-65504.0, min(65504.0, v)) if math.isfinite(v) else v for v in row]
                elif pt not in (1, 2):
                    row = [int(v) & 0xffffffff if math.isfinite(v) else 0 for v in row]
                data += struct.pack('<%d%s' % (len(row), PIXEL_FMT.get(pt, 'I')), *row)
        if zip_:
            half = (len(data) + 1) // 2
            t = bytearray(len(data))
            t[:half], t[half:] = data[0::2], data[1::2]
            for i in range(len(t) - 1, 0, -1):
                t[i] = (t[i] - t[i - 1] + 128) & 0xff
            data = zlib.compress(bytes(t))
        blocks.append(struct.pack('<ii', dw[1] + b, len(data)) + bytes(data))
    off, offsets = len(hdr) + 8 * len(blocks), []
    for bl in blocks:
        offsets.append(off)
        off += len(bl)
    if offset_mut:
        offsets = offset_mut(offsets)
    body = b''.join(struct.pack('<Q', o & 0xffffffffffffffff) for o in offsets) + b''.join(blocks)
    with open(path, 'wb') as f:
        f.write(hdr + body)
