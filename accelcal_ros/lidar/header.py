"""Read a point-cloud file and walk the text header at its start (PCD and PLY)."""
from typing import Iterator, Tuple

from accelcal_ros.errors import FileFormatError, PathLike
from accelcal_ros.fileio import read_input_bytes


def read_file_bytes(path: PathLike, what: str = 'point cloud file') -> bytes:
    """Return the whole content of ``path`` (at most ``SIZE_LIMITS['point cloud']``)."""
    return read_input_bytes(path, what, kind='point cloud')


def header_lines(path: PathLike, raw: bytes,
                 missing_end: str) -> Iterator[Tuple[int, str, int]]:
    """
    Yield ``(line_no, text, offset)`` for each header line of ``raw`` (bytes).

    ``line_no`` counts from 1, ``text`` is the stripped ASCII line and ``offset`` the byte
    offset just after it (where the data starts once the caller sees the last header
    line). Running out of lines raises ``FileFormatError(path, missing_end, line)``.
    """
    offset, line_no = 0, 0
    while True:
        end = raw.find(b'\n', offset)
        if end < 0:
            raise FileFormatError(path, missing_end, line_no + 1)
        line_no += 1
        text = raw[offset:end].decode('ascii', errors='replace').strip()
        offset = end + 1
        yield line_no, text, offset
