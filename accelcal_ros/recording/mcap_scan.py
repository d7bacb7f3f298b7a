"""
How far a cut-short MCAP file can be read (what a damaged bag's error message reports).

An MCAP file that lost its end (the recorder was killed) has no footer and no summary, so
an indexed reader refuses it ("File end magic is invalid"). This scan walks the records
from the start instead (MCAP spec: opcode u8, length u64 LE, content) until the data
runs out, and counts the complete messages on the way: Message records (0x05) at the top
level and inside uncompressed Chunk records (0x06; a compressed chunk counts by its
header's time range only). Nothing is decoded; only the byte layout is read.
"""
from dataclasses import dataclass
import mmap
import struct
from typing import Optional, Tuple, Union

MAGIC = b'\x89MCAP0\r\n'
_MESSAGE, _CHUNK, _FOOTER, _DATA_END = 0x05, 0x06, 0x02, 0x0F

Data = Union[bytes, mmap.mmap]


@dataclass
class McapExtent:
    """What the readable part of an MCAP file holds (times in ns since the epoch)."""

    file_bytes: int
    readable_bytes: int
    messages: int
    first_ns: Optional[int]
    last_ns: Optional[int]
    complete: bool

    def text(self) -> str:
        """Return one sentence: how far the file could be read."""
        if self.messages == 0 or self.first_ns is None or self.last_ns is None:
            return f'its {self.file_bytes} bytes hold no complete message'
        span = (self.last_ns - self.first_ns) / 1e9
        return (f'its {self.file_bytes} bytes were read up to {span:.2f} s after the first '
                f'message ({self.messages} complete messages, log time '
                f'{self.first_ns / 1e9:.3f} to {self.last_ns / 1e9:.3f} s)')


def _messages_in(data: Data, start: int, end: int
                 ) -> Tuple[int, Optional[int], Optional[int]]:
    """Count the complete Message records in ``data[start:end]``; (count, first, last)."""
    count, first, last = 0, None, None
    off = start
    while off + 9 <= end:
        op = data[off]
        (length,) = struct.unpack_from('<Q', data, off + 1)
        if off + 9 + length > end:
            break
        if op == _MESSAGE and length >= 22:
            (log_ns,) = struct.unpack_from('<Q', data, off + 9 + 6)
            count += 1
            first = log_ns if first is None else min(first, log_ns)
            last = log_ns if last is None else max(last, log_ns)
        off += 9 + length
    return count, first, last


def scan_mcap(data: Data) -> McapExtent:
    """Return the :class:`McapExtent` of an MCAP file's bytes (complete or cut short)."""
    size = len(data)
    if data[:8] != MAGIC:
        return McapExtent(size, 0, 0, None, None, False)
    off, count, first, last = 8, 0, None, None

    def merge(n, a, b):
        nonlocal count, first, last
        count += n
        if a is not None:
            first = a if first is None else min(first, a)
            last = b if last is None else max(last, b)

    while off + 9 <= size:
        op = data[off]
        (length,) = struct.unpack_from('<Q', data, off + 1)
        body = off + 9
        if op == _CHUNK and body + 32 <= size:
            (compression_len,) = struct.unpack_from('<I', data, body + 28)
            records_at = body + 32 + compression_len + 8
            compression = data[body + 32:body + 32 + compression_len]
            if compression == b'' and records_at <= size:
                (records_len,) = struct.unpack_from('<Q', data, records_at - 8)
                merge(*_messages_in(data, records_at, min(records_at + records_len, size)))
            elif body + length <= size:
                start_ns, end_ns = struct.unpack_from('<QQ', data, body)
                merge(0, start_ns, end_ns)
        elif op == _MESSAGE and body + length <= size:
            merge(*_messages_in(data, off, body + length))
        if body + length > size:
            return McapExtent(size, off, count, first, last, False)
        if op in (_FOOTER, _DATA_END):
            return McapExtent(size, size, count, first, last, True)
        off = body + length
    return McapExtent(size, off, count, first, last, False)


def scan_mcap_file(path: str) -> McapExtent:
    """Return the :class:`McapExtent` of an MCAP file (memory-mapped, not read whole)."""
    with open(path, 'rb') as handle:
        if handle.seek(0, 2) == 0:
            return McapExtent(0, 0, 0, None, None, False)
        with mmap.mmap(handle.fileno(), 0, access=mmap.ACCESS_READ) as data:
            return scan_mcap(data)
