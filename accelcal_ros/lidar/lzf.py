"""
LZF (liblzf) compression as used by PCL's ``DATA binary_compressed`` PCD files.

Stream format (liblzf ``lzf_d.c``): a control byte ``c``; ``c < 32`` starts a literal
run of ``c + 1`` bytes; otherwise ``len = c >> 5`` (``7`` means "add the next byte") and
the back reference copies ``len + 2`` bytes from ``offset = ((c & 31) << 8) + next + 1``
bytes back (offsets up to 8192, lengths 3..264; a reference may overlap its own output).

Two implementations of the same format, tested against each other:

* the C library liblzf through the maintained ``python-neo-lzf`` package (module ``lzf``)
  when it is installed: about 30-70x faster (one 28,800-point scan: read ~1 ms instead of
  ~28 ms, write ~4 ms instead of ~270 ms; ``benchmarks/bench_pcd_lzf.py``);
* a pure-Python fallback with numpy for the match search: :func:`compress_python` finds,
  for every position, the previous position holding the same 3 bytes with one vectorised
  sort, so the Python loop runs once per emitted token instead of once per byte;
  :func:`decompress_python` copies literal runs and references as slices.

:func:`compress` and :func:`decompress` use the C one when present (:data:`BACKEND` says
which; ``ACCELCAL_LZF=python`` forces the fallback). Streams written by either are read by
PCL and by the other.
"""
import os
from typing import Optional, Union

import numpy as np

try:
    import lzf as _clzf
except ImportError:  # python-neo-lzf not installed: pure Python below
    _clzf = None

#: what the functions take: any bytes-like object
BytesLike = Union[bytes, bytearray, memoryview]

MAX_OFFSET = 8192
MAX_LITERAL = 32
MAX_MATCH = 264
#: the most output one compressed byte can stand for (a 3-byte reference copies 264 bytes)
MAX_RATIO = MAX_MATCH // 3


class LzfError(ValueError):
    """The compressed stream is corrupt or does not match the expected size."""

    def __init__(self, message: str, offset: Optional[int] = None) -> None:
        self.offset = offset
        super().__init__(message if offset is None else
                         f'{message} (at compressed byte {offset})')


def c_available() -> bool:
    """Whether the C implementation (package ``python-neo-lzf``) is installed."""
    return _clzf is not None


def _use_c() -> bool:
    return _clzf is not None and os.environ.get('ACCELCAL_LZF', '').lower() != 'python'


BACKEND = 'c' if _use_c() else 'python'


def compress(data: BytesLike) -> bytes:
    """Return ``data`` LZF-compressed (C liblzf when installed, else pure Python)."""
    return compress_c(data) if _use_c() else compress_python(data)


def decompress(data: BytesLike, expected_size: int) -> bytes:
    """Return the ``expected_size`` bytes encoded in ``data``; :class:`LzfError` if corrupt."""
    return decompress_c(data, expected_size) if _use_c() else \
        decompress_python(data, expected_size)


def compress_c(data: BytesLike) -> bytes:
    """Compress with liblzf (``python-neo-lzf``); the stream never exceeds the worst case."""
    raw = bytes(data)
    if not raw:
        return b''
    # liblzf's worst case: one control byte per 32 literals
    out = _clzf.compress(raw, len(raw) + len(raw) // 32 + 16)
    if out is None:  # cannot happen within the worst-case bound; be safe
        return compress_python(raw)
    return bytes(out)


def decompress_c(data: BytesLike, expected_size: int) -> bytes:
    """Decompress with liblzf; :class:`LzfError` when corrupt or not ``expected_size``."""
    src = bytes(data)
    if expected_size == 0 or not src:
        if expected_size == 0 and not src:
            return b''
        raise LzfError(f'stream of {len(src)} bytes cannot hold {expected_size} bytes')
    try:
        out = _clzf.decompress(src, expected_size)
    except ValueError as exc:
        raise LzfError(f'corrupt stream ({exc})') from None
    if out is None:
        raise LzfError(f'stream is corrupt or decodes to more than {expected_size} bytes')
    if len(out) != expected_size:
        raise LzfError(f'stream ends after {len(out)} of {expected_size} expected bytes')
    return bytes(out)


def decompress_python(data: BytesLike, expected_size: int) -> bytes:
    """Pure-Python :func:`decompress` (the fallback; same errors)."""
    src = bytes(data)
    out = bytearray()
    n = len(src)
    i = 0
    while i < n:
        ctrl = src[i]
        i += 1
        if ctrl < 32:
            run = ctrl + 1
            if i + run > n:
                raise LzfError(f'literal run of {run} bytes runs past the end of the data', i - 1)
            out += src[i:i + run]
            i += run
        else:
            length = ctrl >> 5
            if length == 7:
                if i >= n:
                    raise LzfError('back reference length byte missing', i - 1)
                length += src[i]
                i += 1
            if i >= n:
                raise LzfError('back reference offset byte missing', i - 1)
            offset = ((ctrl & 31) << 8) + src[i] + 1
            i += 1
            length += 2
            start = len(out) - offset
            if start < 0:
                raise LzfError(f'back reference {offset} bytes before the start of the output',
                               i - 2)
            if offset >= length:
                out += out[start:start + length]
            else:
                pattern = bytes(out[start:])
                out += (pattern * (length // offset + 1))[:length]
        if len(out) > expected_size:
            raise LzfError(f'output exceeds the expected {expected_size} bytes', i)
    if len(out) != expected_size:
        raise LzfError(f'stream ends after {len(out)} of {expected_size} expected bytes', n)
    return bytes(out)


def _previous_match(buf):
    """For every position, the previous position with the same 3 bytes (-1 if none)."""
    n = buf.size
    prev = np.full(n, -1, dtype=np.int64)
    if n < 3:
        return prev
    b = buf.astype(np.int64)
    key = (b[:-2] << 16) | (b[1:-1] << 8) | b[2:]
    order = np.argsort(key, kind='stable')
    same = key[order[1:]] == key[order[:-1]]
    prev[order[1:][same]] = order[:-1][same]
    return prev


def compress_python(data: BytesLike) -> bytes:
    """Return ``data`` (bytes-like) LZF-compressed in pure Python (greedy, nearest match)."""
    raw = bytes(data)
    n = len(raw)
    if n == 0:
        return b''
    buf = np.frombuffer(raw, dtype=np.uint8)
    prev = _previous_match(buf)
    pos = np.arange(n)
    usable = (prev >= 0) & (pos - prev <= MAX_OFFSET)
    usable[max(n - 2, 0):] = False
    candidates = np.flatnonzero(usable)
    prev_list = prev.tolist()
    out = bytearray()
    literal_start = 0
    i = 0
    k = 0
    ncand = candidates.size
    while True:
        k = int(np.searchsorted(candidates, i)) if k < ncand and candidates[k] < i else k
        if k >= ncand:
            break
        i = int(candidates[k])
        j = prev_list[i]
        limit = min(MAX_MATCH, n - i)
        length = 3
        # extend the match (the source may overlap the output; compare original bytes)
        while length < limit and raw[j + length] == raw[i + length]:
            length += 1
        _emit_literals(out, raw, literal_start, i)
        offset = i - j - 1
        code = length - 2
        if code < 7:
            out.append((code << 5) | (offset >> 8))
        else:
            out.append((7 << 5) | (offset >> 8))
            out.append(code - 7)
        out.append(offset & 255)
        i += length
        literal_start = i
    _emit_literals(out, raw, literal_start, n)
    return bytes(out)


def _emit_literals(out, raw, start, end):
    while start < end:
        run = min(MAX_LITERAL, end - start)
        out.append(run - 1)
        out += raw[start:start + run]
        start += run
