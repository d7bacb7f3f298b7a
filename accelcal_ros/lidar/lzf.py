"""
LZF (liblzf) compression as used by PCL's ``DATA binary_compressed`` PCD files.

Stream format (liblzf ``lzf_d.c``): a control byte ``c``; ``c < 32`` starts a literal
run of ``c + 1`` bytes; otherwise ``len = c >> 5`` (``7`` means "add the next byte") and
the back reference copies ``len + 2`` bytes from ``offset = ((c & 31) << 8) + next + 1``
bytes back (offsets up to 8192, lengths 3..264; a reference may overlap its own output).

Pure Python with numpy for the match search: :func:`compress` finds, for every position,
the previous position holding the same 3 bytes with one vectorised sort, so the Python
loop runs once per emitted token instead of once per byte; :func:`decompress` copies
literal runs and references as slices. Streams written here are read by PCL and back.
"""
import numpy as np

MAX_OFFSET = 8192
MAX_LITERAL = 32
MAX_MATCH = 264


class LzfError(ValueError):
    """The compressed stream is corrupt or does not match the expected size."""

    def __init__(self, message, offset):
        self.offset = offset
        super().__init__(f'{message} (at compressed byte {offset})')


def decompress(data, expected_size):
    """Return the ``expected_size`` bytes encoded in ``data``; :class:`LzfError` if corrupt."""
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


def compress(data):
    """Return ``data`` (bytes-like) LZF-compressed (greedy, nearest 3-byte match)."""
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
