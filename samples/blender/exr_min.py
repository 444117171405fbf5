"""exr_min.py: a minimal OpenEXR reader and writer in pure Python + numpy.

Written for mcpost's sample fixtures (samples/README.md). It covers only what
Blender's multilayer output and our fixtures need:

  * single-part scanline images (no tiles, no deep data, no multi-part);
  * pixel types UINT, HALF and FLOAT;
  * compression NONE, ZIPS and ZIP on read; NONE and ZIP on write;
  * header attributes of type int, float, double, string, box2i, v2f,
    compression, lineOrder and chlist (others are kept as raw bytes).

Format facts used here (OpenEXR file layout, "Technical Introduction"):
  magic 20000630, version field 2 (+0x400 when names exceed 31 bytes);
  header = sequence of (name\\0, type\\0, int32 size, value), ended by \\0;
  offset table = one uint64 file offset per chunk;
  scanline chunk = int32 y, int32 byte count, data; inside the data, each
  scanline holds every channel (in chlist order, which is sorted by name)
  as `width` little-endian values.
  ZIP: zlib over blocks of 16 scanlines (ZIPS: 1) after splitting the bytes
  into even and odd positions and replacing each byte by its difference to
  the previous one (+128). A chunk whose compressed form would not be
  smaller is stored raw.

No third-party code was copied; this is a fresh implementation.
"""

import struct
import zlib

import numpy as np

MAGIC = 20000630

UINT, HALF, FLOAT = 0, 1, 2
_DTYPE = {UINT: np.dtype('<u4'), HALF: np.dtype('<f2'), FLOAT: np.dtype('<f4')}
_TYPE_OF = {'uint': UINT, 'half': HALF, 'float': FLOAT}

COMP_NONE, COMP_RLE, COMP_ZIPS, COMP_ZIP = 0, 1, 2, 3
_LINES_PER_CHUNK = {0: 1, 1: 1, 2: 1, 3: 16, 4: 32, 5: 16, 6: 32, 7: 32, 8: 32, 9: 256}
_COMP_NAME = {0: 'none', 1: 'rle', 2: 'zips', 3: 'zip', 4: 'piz', 5: 'pxr24',
              6: 'b44', 7: 'b44a', 8: 'dwaa', 9: 'dwab'}

HALF_MAX = 65504.0


class ExrError(Exception):
    pass


# ---------------------------------------------------------------- predictor

def _zip_decode(raw, expected):
    """Undo EXR's ZIP filter: zlib, then delta predictor, then interleave."""
    t = np.frombuffer(zlib.decompress(raw), dtype=np.uint8)
    if t.size != expected:
        raise ExrError('zip chunk: got %d bytes, expected %d' % (t.size, expected))
    # predictor: t[i] = t[i-1] + t[i] - 128 (mod 256); a cumulative sum
    d = t.astype(np.int64)
    d[1:] -= 128
    t = (np.cumsum(d) & 0xFF).astype(np.uint8)
    half = (t.size + 1) // 2
    out = np.empty(t.size, dtype=np.uint8)
    out[0::2] = t[:half]
    out[1::2] = t[half:]
    return out.tobytes()


def _zip_encode(raw):
    """EXR's ZIP filter: split even/odd bytes, delta predictor, zlib."""
    b = np.frombuffer(raw, dtype=np.uint8)
    t = np.concatenate([b[0::2], b[1::2]])
    d = t.astype(np.int16)
    d[1:] = (d[1:] - d[:-1] + 128) & 0xFF
    return zlib.compress(d.astype(np.uint8).tobytes(), 6)


# ------------------------------------------------------------------- reader

def _cstr(buf, pos):
    end = buf.index(b'\0', pos)
    return buf[pos:end].decode('latin-1'), end + 1


def _parse_attr(typ, val):
    if typ == 'int':
        return struct.unpack('<i', val)[0]
    if typ == 'float':
        return struct.unpack('<f', val)[0]
    if typ == 'double':
        return struct.unpack('<d', val)[0]
    if typ == 'string':
        return val.decode('utf-8', 'replace')
    if typ in ('compression', 'lineOrder'):
        return val[0]
    if typ == 'box2i':
        return struct.unpack('<4i', val)
    if typ == 'v2f':
        return struct.unpack('<2f', val)
    if typ == 'chlist':
        chans, pos = [], 0
        while val[pos] != 0:
            name, pos = _cstr(val, pos)
            ptype, plin, xs, ys = struct.unpack_from('<iB3xii', val, pos)
            pos += 16
            chans.append((name, ptype, plin, xs, ys))
        return chans
    return val


def read_header(buf):
    """Return (attrs, types, position after header) for an EXR byte string."""
    magic, version = struct.unpack_from('<ii', buf, 0)
    if magic != MAGIC:
        raise ExrError('not an OpenEXR file')
    if (version & 0xFF) != 2:
        raise ExrError('unsupported EXR version %d' % (version & 0xFF))
    if version & 0x200:
        raise ExrError('tiled images are not supported')
    if version & 0x1800:
        raise ExrError('deep or multi-part images are not supported')
    pos = 8
    attrs, types = {}, {}
    while buf[pos] != 0:
        name, pos = _cstr(buf, pos)
        typ, pos = _cstr(buf, pos)
        size = struct.unpack_from('<i', buf, pos)[0]
        pos += 4
        attrs[name] = _parse_attr(typ, buf[pos:pos + size])
        types[name] = typ
        pos += size
    return attrs, types, pos + 1


def read(path):
    """Read a scanline EXR.

    Returns (channels, attrs): channels maps a channel name to a float32
    array of shape (height, width), top row first; attrs maps attribute
    names to parsed values (ints, floats, strings, tuples, chlist lists).
    """
    with open(path, 'rb') as f:
        buf = f.read()
    attrs, _types, pos = read_header(buf)
    comp = attrs['compression']
    if comp not in (COMP_NONE, COMP_ZIPS, COMP_ZIP):
        raise ExrError('%s: compression %s not supported'
                       % (path, _COMP_NAME.get(comp, comp)))
    x0, y0, x1, y1 = attrs['dataWindow']
    w, h = x1 - x0 + 1, y1 - y0 + 1
    chans = attrs['channels']
    for c in chans:
        if c[3] != 1 or c[4] != 1:
            raise ExrError('%s: subsampled channel %s' % (path, c[0]))
    lpc = _LINES_PER_CHUNK[comp]
    nchunks = (h + lpc - 1) // lpc
    offsets = struct.unpack_from('<%dQ' % nchunks, buf, pos)
    line_dtype = np.dtype([(c[0], _DTYPE[c[1]], (w,)) for c in chans])
    out = {c[0]: np.empty((h, w), dtype=np.float32) for c in chans}
    for off in offsets:
        y, size = struct.unpack_from('<ii', buf, off)
        data = buf[off + 8:off + 8 + size]
        row = y - y0
        nlines = min(lpc, h - row)
        expected = nlines * line_dtype.itemsize
        if comp != COMP_NONE and size < expected:
            data = _zip_decode(data, expected)
        if len(data) != expected:
            raise ExrError('%s: chunk at y=%d has %d bytes, expected %d'
                           % (path, y, len(data), expected))
        lines = np.frombuffer(data, dtype=line_dtype, count=nlines)
        for c in chans:
            out[c[0]][row:row + nlines] = lines[c[0]]
    return out, attrs


# ------------------------------------------------------------------- writer

def _attr(name, typ, payload):
    return (name.encode('latin-1') + b'\0' + typ.encode('latin-1') + b'\0'
            + struct.pack('<i', len(payload)) + payload)


def write(path, channels, attrs=None, pixel_type=HALF, compression=COMP_ZIP,
          pixel_types=None):
    """Write a single-part scanline EXR.

    channels: dict name -> 2-D array (height, width), top row first; all the
    same shape. pixel_type: HALF or FLOAT for every channel, overridden per
    channel by pixel_types (dict name -> type). attrs: extra header
    attributes, dict name -> value where a Python int is written as 'int',
    a float as 'float' and a str as 'string'. Values outside the half range
    are NOT clamped here; the caller decides (see clamp_half).
    Returns the number of bytes written.
    """
    if compression not in (COMP_NONE, COMP_ZIP):
        raise ExrError('writer supports only NONE and ZIP')
    names = sorted(channels)  # OpenEXR orders channels by byte value
    shapes = {np.shape(channels[n]) for n in names}
    if len(shapes) != 1:
        raise ExrError('channels differ in shape: %s' % shapes)
    h, w = shapes.pop()
    ptypes = {n: pixel_type for n in names}
    if pixel_types:
        ptypes.update(pixel_types)

    long_names = False
    chl = b''
    for n in names:
        chl += n.encode('latin-1') + b'\0' + struct.pack('<iB3xii', ptypes[n], 0, 1, 1)
        long_names |= len(n) > 31
    chl += b'\0'
    hdr = [
        _attr('channels', 'chlist', chl),
        _attr('compression', 'compression', bytes([compression])),
        _attr('dataWindow', 'box2i', struct.pack('<4i', 0, 0, w - 1, h - 1)),
        _attr('displayWindow', 'box2i', struct.pack('<4i', 0, 0, w - 1, h - 1)),
        _attr('lineOrder', 'lineOrder', bytes([0])),
        _attr('pixelAspectRatio', 'float', struct.pack('<f', 1.0)),
        _attr('screenWindowCenter', 'v2f', struct.pack('<2f', 0.0, 0.0)),
        _attr('screenWindowWidth', 'float', struct.pack('<f', 1.0)),
    ]
    for k, v in sorted((attrs or {}).items()):
        long_names |= len(k) > 31
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            raise ExrError('attribute %s: unsupported value %r' % (k, v))
        if isinstance(v, int):
            hdr.append(_attr(k, 'int', struct.pack('<i', v)))
        elif isinstance(v, float):
            hdr.append(_attr(k, 'float', struct.pack('<f', v)))
        else:
            hdr.append(_attr(k, 'string', v.encode('utf-8')))
    version = 2 | (0x400 if long_names else 0)
    head = struct.pack('<ii', MAGIC, version) + b''.join(hdr) + b'\0'

    line_dtype = np.dtype([(n, _DTYPE[ptypes[n]], (w,)) for n in names])
    lines = np.empty(h, dtype=line_dtype)
    for n in names:
        lines[n] = np.asarray(channels[n]).astype(_DTYPE[ptypes[n]])
    lpc = _LINES_PER_CHUNK[compression]
    nchunks = (h + lpc - 1) // lpc
    chunks = []
    for i in range(nchunks):
        raw = lines[i * lpc:(i + 1) * lpc].tobytes()
        if compression == COMP_ZIP:
            z = _zip_encode(raw)
            if len(z) < len(raw):
                raw = z
        chunks.append(struct.pack('<ii', i * lpc, len(raw)) + raw)
    pos = len(head) + 8 * nchunks
    table = []
    for c in chunks:
        table.append(pos)
        pos += len(c)
    blob = head + struct.pack('<%dQ' % nchunks, *table) + b''.join(chunks)
    with open(path, 'wb') as f:
        f.write(blob)
    return len(blob)


def clamp_half(a):
    """Clamp to the finite half range (as pbrt-v4 does for fp16 output).

    Returns (clamped float32 array, number of values that were clamped)."""
    a = np.asarray(a, dtype=np.float64)
    bad = np.abs(a) > HALF_MAX
    return np.clip(a, -HALF_MAX, HALF_MAX).astype(np.float32), int(bad.sum())
