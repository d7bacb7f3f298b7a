"""
Special files and size limits: what the readers and the writer of :mod:`.fileio` check.

A path is read only when ``os.stat`` says it is a regular file, opened with
``O_NONBLOCK`` (a FIFO swapped in cannot block the open) and checked again with
``fstat``; :data:`SIZE_LIMITS` states the most bytes read per format. An output replaces
only a regular file (or nothing): :func:`existing_output_problem` says why a path cannot be
one (a directory, ``/dev/full``, a FIFO).
"""
import contextlib
import os
import stat
from typing import IO, Iterator, Optional

from accelcal_ros.errors import FileFormatError, PathLike

#: most bytes read from one file, per format (a file beyond is refused before it is read
#: whole): the YAML files this package writes (calibration ~3 kB + ~70 B per captured
#: position, rig ~2 kB per camera, boresight, camera_info, reports) are kilobytes; the
#: largest YAML it reads is a rosbag2 ``metadata.yaml`` (~1.1 kB per topic, ~190 B per split
#: file: 1000 topics and 4000 split files are 1.4 MB), hence 4 MiB; what bounds the parse
#: time (about a second) is ``textformats.MAX_YAML_SEPARATORS``. A CSV (an accelerometer
#: recording at 3200 Hz for an hour is ~0.5 GB), a point cloud and an image are bounded far
#: above anything real and below what fits in memory. Keys are the ``kind`` argument of
#: :func:`read_input_bytes`.
SIZE_LIMITS = {
    'yaml': 4 * 2**20,
    'csv': 1 * 2**30,
    'point cloud': 2 * 2**30,
    'image': 512 * 2**20,
    'text line': 1 * 2**20,
    'file': 1 * 2**30,
}


def file_kind(mode: int) -> str:
    """Return what a non-regular file is, in words (``character device``...)."""
    for test, name in ((stat.S_ISDIR, 'directory'), (stat.S_ISCHR, 'character device'),
                       (stat.S_ISBLK, 'block device'), (stat.S_ISFIFO, 'FIFO (named pipe)'),
                       (stat.S_ISSOCK, 'socket')):
        if test(mode):
            return name
    return 'special file'


def check_regular_file(path: PathLike, what: str = 'file') -> os.stat_result:
    """
    Return ``os.stat(path)`` of an existing regular file; FileFormatError otherwise.

    A missing path, a directory, a device (``/dev/zero``), a FIFO or a socket is refused
    before anything opens it (opening a FIFO blocks; a device never ends).
    """
    path = os.fspath(path)
    if not path:
        raise FileFormatError('""', f'empty path given for the {what}')
    try:
        info = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise FileFormatError(path, f'{what} not found') from None
    except OSError as exc:
        raise FileFormatError(path, f'cannot read {what}: {exc.strerror or exc}') from None
    except ValueError as exc:  # a NUL byte in the path
        raise FileFormatError(repr(path), f'invalid path for the {what} ({exc})') from None
    if stat.S_ISDIR(info.st_mode):
        raise FileFormatError(path, f'is a directory, expected a {what}')
    if not stat.S_ISREG(info.st_mode):
        raise FileFormatError(path, f'is a {file_kind(info.st_mode)}, not a regular file: '
                              f'the {what} must be a file on disk')
    return info


@contextlib.contextmanager
def open_regular_file(path: PathLike, what: str = 'file') -> Iterator[IO[bytes]]:
    """
    Open an existing regular file for reading (binary) without following it into a device.

    Checked with ``os.stat`` first, opened with ``O_NONBLOCK`` (a FIFO swapped in between
    cannot block the open) and checked again with ``fstat`` on the open descriptor.
    """
    path = os.fspath(path)
    check_regular_file(path, what)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, 'O_CLOEXEC', 0))
    except OSError as exc:
        raise FileFormatError(path, f'cannot read {what}: {exc.strerror or exc}') from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise FileFormatError(path, f'is a {file_kind(mode)}, not a regular file: '
                                  f'the {what} must be a file on disk')
        os.set_blocking(fd, True)
        handle = os.fdopen(fd, 'rb')
    except BaseException:
        os.close(fd)
        raise
    with handle:
        yield handle


def existing_output_problem(path: PathLike) -> Optional[str]:
    """
    Return why ``path`` cannot be an output file (empty, a directory, a device...), or None.

    For the nodes' ``output_file`` parameters: checked when the value is set, so a bad
    path is refused at once rather than after a calibration was captured.
    """
    path = os.path.expanduser(os.fspath(path))
    if not path:
        return 'empty: give the path of the file to write'
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return None  # a new file (whether its place is writable shows when it is written)
    if stat.S_ISDIR(info.st_mode):
        return f'{path} is a directory; give a file name'
    if not stat.S_ISREG(info.st_mode):
        return (f'{path} is a {file_kind(info.st_mode)}, not a regular file: an output '
                'replaces only a regular file (or creates a new one)')
    return None
