"""
File helpers: reading with clear errors, atomic writes that keep the user's files.

Reading: :func:`read_input_bytes` / :func:`read_input_text` are the one place where a file
is opened for reading; a missing file, a directory, a permission problem or bytes that are
not UTF-8 become a :class:`~accelcal_ros.errors.FileFormatError` naming the file (and the
line of a bad byte). The YAML and CSV readers (:mod:`accelcal_ros.textformats`) and the
PCD/PLY readers go through them.

Writing: data goes to a temporary file ``.<name>.<pid>-<n>.accelcal-tmp`` in the target's
directory, is flushed and fsync'ed, then ``os.replace`` puts it in place (atomic on POSIX).
An existing file keeps its permission bits; a new one gets ``0666 & ~umask`` like any
file the user creates; a symbolic link is written through (it stays a link). Temporary
files that a killed writer left next to the target (their pid no longer runs) are removed
first. Any failure (read-only place, ``/proc``, a directory as target, no room) is a
:class:`~accelcal_ros.errors.FileWriteError` naming the path. Only a regular file (or
nothing) is replaced: a device such as ``/dev/null`` or ``/dev/full``, a FIFO or a socket
at the target is refused before anything is written. With ``backup=True`` the previous
file is kept as ``<name>.bak`` by a hard link (a rename where links are not possible),
never by a copy.

Reading never follows a path into a device, FIFO or socket and reads at most
``SIZE_LIMITS`` bytes per format (:mod:`accelcal_ros.filecheck`).

Inside :func:`guard_inputs` (the ``accelcal`` dispatcher wraps every command in it) every
file read through this module and every path given to it counts as an input: writing to an
input (same resolved path or same inode) is refused with an :class:`InputError` unless the
writer keeps a backup; a path inside an input bag directory, or an existing file inside
any input directory, is refused always.
"""
import contextlib
import io
import itertools
import os
import re
import stat
import threading
from typing import Any, Callable, Dict, IO, Iterable, Iterator, List, Optional, Set, Tuple

from accelcal_ros.errors import FileFormatError, FileWriteError, InputError, PathLike
from accelcal_ros.filecheck import file_kind, open_regular_file, SIZE_LIMITS

TEMP_SUFFIX = '.accelcal-tmp'
_TEMP_PATTERN = re.compile(r'^\.(?P<name>.+)\.(?P<pid>\d+)-\d+' + re.escape(TEMP_SUFFIX) + '$')
_counter = itertools.count()
_guard = threading.local()


# ---------------------------------------------------------------------------------------
# reading


def _identity(path):
    """Return ``(device, inode)`` of an existing path, else None."""
    try:
        info = os.stat(path)
    except (OSError, ValueError):
        return None
    return info.st_dev, info.st_ino


def record_input(path: PathLike) -> None:
    """Count ``path`` (a file or a directory such as a bag) as an input of the command."""
    _record_input(os.fspath(path))


def _record_input(path):
    inputs = getattr(_guard, 'inputs', None)
    if inputs is not None:
        ident = _identity(path)
        inputs[os.path.realpath(path)] = (path, ident)


def read_input_bytes(path: PathLike, what: str = 'file', kind: str = 'file') -> bytes:
    """
    Return the whole content of ``path`` (bytes); FileFormatError if it cannot be read.

    A missing file, a directory, a device, FIFO or socket, a permission problem or a file
    larger than ``SIZE_LIMITS[kind]`` is reported with the path and what the file was
    meant to be (``what``).
    """
    path = os.fspath(path)
    limit = SIZE_LIMITS[kind]
    try:
        with open_regular_file(path, what) as handle:
            size = os.fstat(handle.fileno()).st_size
            if size > limit:
                raise FileFormatError(path, _too_large(what, kind, size))
            data = handle.read(limit + 1)
    except MemoryError:
        raise FileFormatError(path, f'{what} is too large to read') from None
    except OSError as exc:
        raise FileFormatError(path, f'cannot read {what}: {exc.strerror or exc}') from None
    if len(data) > limit:  # grew while read, or a /proc-like file with no size
        raise FileFormatError(path, _too_large(what, kind, len(data)))
    _record_input(path)
    return data


def read_image_file(path: PathLike, flags: int, what: str = 'image') -> Any:
    """
    Decode an image file with OpenCV (``cv2.imdecode`` with ``flags``); None if undecodable.

    The bytes go through :func:`read_input_bytes` (a regular file of at most
    ``SIZE_LIMITS['image']`` bytes), so a device or FIFO is refused, not read forever.
    """
    import cv2
    import numpy as np

    data = read_input_bytes(path, what, kind='image')
    if not data:
        return None
    try:
        return cv2.imdecode(np.frombuffer(data, dtype=np.uint8), flags)
    except cv2.error:
        return None


def open_text_lines(path: PathLike, what: str = 'file') -> Iterator[str]:
    """
    Yield the lines of a text file (undecodable bytes replaced), each at most 1 MiB.

    The file must be a regular file (see :func:`open_regular_file`); a longer line is a
    FileFormatError naming its number.
    """
    path = os.fspath(path)
    limit = SIZE_LIMITS['text line']
    with open_regular_file(path, what) as raw:
        _record_input(path)
        number = 0
        while True:
            line = raw.readline(limit + 1)
            if not line:
                return
            number += 1
            if len(line) > limit and not line.endswith(b'\n'):
                raise FileFormatError(path, f'line longer than {limit // 2**20} MiB; not a '
                                      f'{what}', number)
            yield line.decode('utf-8', errors='replace')


def _too_large(what: str, kind: str, size: int) -> str:
    limit = SIZE_LIMITS[kind]
    return (f'{what} is larger ({size} bytes or more) than the {limit // 2**20} MiB this '
            f'package reads from a {kind} file; not a file of this package (or split it)')


def decode_text(path: PathLike, data: bytes, what: str = 'file') -> str:
    """Decode ``data`` as UTF-8 (BOM allowed); FileFormatError with the line of a bad byte."""
    try:
        return data.decode('utf-8-sig')
    except UnicodeDecodeError as exc:
        line = data[:exc.start].count(b'\n') + 1
        raise FileFormatError(path, f'{what} is not UTF-8 text (byte 0x{data[exc.start]:02x} '
                              f'at offset {exc.start}); is this the right file?', line) from None


def read_input_text(path: PathLike, what: str = 'file', kind: str = 'file') -> str:
    """Return the content of ``path`` as text (UTF-8); see :func:`read_input_bytes`."""
    path = os.fspath(path)
    return decode_text(path, read_input_bytes(path, what, kind), what)


# ---------------------------------------------------------------------------------------
# guarding the inputs of a command


@contextlib.contextmanager
def guard_inputs(paths: Iterable[Optional[PathLike]] = ()) -> Iterator[None]:
    """
    Within the block, refuse to write over any input: ``paths`` and every file read here.

    Used by the ``accelcal`` dispatcher around each command (``paths``: the command's
    arguments that name existing files). A write with ``backup=True`` is allowed (the
    input survives as ``.bak``).
    """
    previous = getattr(_guard, 'inputs', None)
    _guard.inputs = {}
    try:
        for path in paths:
            if path and os.path.exists(path):
                _record_input(os.fspath(path))
        yield
    finally:
        _guard.inputs = previous


def refuse_overwriting_inputs(output: PathLike, inputs: Iterable[Optional[PathLike]]) -> None:
    """
    Raise InputError when ``output`` is one of ``inputs`` or lies inside an input directory.

    Same resolved path or same inode; inside an input directory an existing file (a data
    set's image) and anything in a bag (its ``metadata.yaml``, a new file beside its
    storage) are refused too; a new file beside a data set's files is not.
    """
    output = os.fspath(output)
    out_real = os.path.realpath(output)
    out_ident = _identity(output)
    for given in inputs:
        if given is None:
            continue
        given = os.fspath(given)
        given_real = os.path.realpath(given)
        same = given_real == out_real or (
            out_ident is not None and _identity(given) == out_ident)
        if same:
            raise InputError(f'{output}: this is also an input of the command ({given}); '
                             'writing it would destroy the input: choose another output path')
        inside = os.path.isdir(given_real) and \
            out_real.startswith(given_real.rstrip(os.sep) + os.sep)
        if inside and (os.path.lexists(out_real) or _is_bag_directory(given_real)):
            raise InputError(f'{output}: this is inside {given}, a directory the command '
                             'reads (a bag is a directory); writing there would change the '
                             'input: choose an output path outside it')
        if os.path.isdir(given_real):
            real_paths, identities = _directory_files(given_real)
            if out_real in real_paths or out_ident in identities:
                raise InputError(f'{output}: this is a file of {given}, an input of the '
                                 'command (through a link); writing it would destroy the '
                                 'input: choose another output path')


def missing_folders(path: PathLike) -> List[str]:
    """
    Return the folders of ``path`` (itself included) that do not exist yet, outermost first.

    What ``os.makedirs(path)`` would make; with :func:`remove_empty_folders` a failed run
    takes away exactly the folders it made.
    """
    missing: List[str] = []
    folder = os.path.abspath(os.fspath(path))
    while not os.path.isdir(folder):
        missing.insert(0, folder)
        folder = os.path.dirname(folder)
    return missing


def remove_empty_folders(folders: Iterable[str]) -> None:
    """
    Remove ``folders`` (outermost first, as :func:`missing_folders`), innermost first.

    Each only if empty: one something else was put in stays, and so do those around it.
    """
    for folder in reversed(list(folders)):
        try:
            os.rmdir(folder)
        except OSError:
            pass


DIRECTORY_FILES_LISTED = 100000
"""Files of an input directory (two levels) compared with an output; beyond, no more."""
_directory_cache: Dict[Tuple[str, int], Tuple[Set[str], Set[Tuple[int, int]]]] = {}


def _directory_files(path: str) -> Tuple[Set[str], Set[Tuple[int, int]]]:
    """
    Return the resolved paths and ``(device, inode)`` of the files in directory ``path``.

    Its files and those of its sub-folders (a bag's storage, a data set's images, a
    capture's camera folders), links followed: a bag whose ``.mcap`` is a link to a file
    elsewhere, or a hard link, is that file. Kept per directory state (its mtime).
    """
    try:
        key = (path, os.stat(path).st_mtime_ns)
    except OSError:
        return set(), set()
    if key in _directory_cache:
        return _directory_cache[key]
    real_paths: Set[str] = set()
    identities: Set[Tuple[int, int]] = set()
    folders = [(path, 0)]
    while folders and len(real_paths) < DIRECTORY_FILES_LISTED:
        folder, depth = folders.pop()
        try:
            entries = list(os.scandir(folder))
        except OSError:
            continue
        for entry in entries:
            if len(real_paths) >= DIRECTORY_FILES_LISTED:
                break
            try:
                if entry.is_dir():
                    if depth < 1:
                        folders.append((entry.path, depth + 1))
                    continue
                info = entry.stat()
            except OSError:
                continue
            real_paths.add(os.path.realpath(entry.path))
            identities.add((info.st_dev, info.st_ino))
    if len(_directory_cache) > 64:
        _directory_cache.clear()
    _directory_cache[key] = (real_paths, identities)
    return real_paths, identities


def _is_bag_directory(path):
    """Whether a directory is a rosbag2 recording (metadata.yaml or storage files in it)."""
    try:
        names = os.listdir(path)
    except OSError:
        return False
    return 'metadata.yaml' in names or any(n.endswith(('.mcap', '.db3')) for n in names)


def _check_guard(path, backup=False):
    inputs = getattr(_guard, 'inputs', None)
    if not inputs:
        return
    given = [g for g, _ in inputs.values()]
    if backup:  # the input file survives as .bak, but a directory read must stay as it was
        given = [g for g in given if os.path.isdir(g)]
    refuse_overwriting_inputs(path, given)


# ---------------------------------------------------------------------------------------
# writing


def _umask():
    try:
        with open('/proc/self/status') as handle:
            for line in handle:
                if line.startswith('Umask:'):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    mask = os.umask(0o022)  # (not thread-safe; only where /proc is missing)
    os.umask(mask)
    return mask


def _pid_alive(pid):
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def remove_stale_temp_files(path: PathLike) -> List[str]:
    """Remove temporary files of ``path`` left by writers that no longer run; return them."""
    directory = os.path.dirname(os.path.abspath(path))
    name = os.path.basename(path)
    removed: List[str] = []
    try:
        entries = os.listdir(directory)
    except OSError:
        return removed
    for entry in entries:
        match = _TEMP_PATTERN.match(entry)
        if match and match.group('name') == name and not _pid_alive(int(match.group('pid'))):
            try:
                os.unlink(os.path.join(directory, entry))
                removed.append(entry)
            except OSError:
                pass
    return removed


def _temp_name(path):
    directory = os.path.dirname(os.path.abspath(path))
    return os.path.join(directory, f'.{os.path.basename(path)}.{os.getpid()}-'
                                   f'{next(_counter)}{TEMP_SUFFIX}')


def _write_file(target, data, mode):
    """Write ``data`` to a new temporary file beside ``target``; return its path."""
    tmp = _temp_name(target)
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    try:
        with os.fdopen(fd, 'wb') as handle:
            os.fchmod(handle.fileno(), mode)
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
    return tmp


def _existing_target(path, shown):
    """Return the stat of an existing target, None if there is none; refuse non-files."""
    try:
        info = os.stat(path)
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise FileWriteError(shown, f'cannot write: {exc.strerror or exc}') from None
    except ValueError as exc:  # a NUL byte in the path
        raise FileWriteError(repr(shown), f'invalid path ({exc})') from None
    if stat.S_ISDIR(info.st_mode):
        raise FileWriteError(shown, 'is a directory; give a file name')
    if not stat.S_ISREG(info.st_mode):
        raise FileWriteError(shown, f'is a {file_kind(info.st_mode)}, not a regular file: '
                             'an output replaces only a regular file (or creates a new one); '
                             'give a file path')
    return info


def _keep_backup(path):
    """
    Keep the current ``path`` as ``path.bak`` without copying it.

    A hard link under a temporary name renamed onto ``.bak`` (``path`` stays in place
    until the new file replaces it); where the file system has no hard links the file is
    renamed to ``.bak`` (``path`` is then briefly missing).
    """
    bak = path + '.bak'
    tmp_bak = _temp_name(bak)
    try:
        os.link(path, tmp_bak)
    except OSError:
        os.replace(path, bak)
        return
    try:
        os.replace(tmp_bak, bak)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp_bak)
        raise


def write_bytes_atomic(path: PathLike, data: bytes, backup: bool = False) -> None:
    """
    Write ``data`` (bytes) to ``path`` atomically; keep the old file as ``path.bak``.

    Only a regular file (or nothing) is replaced: a directory, a device (``/dev/null``),
    a FIFO or a socket at ``path`` is refused before anything is written. Raises
    :class:`FileWriteError` (one line naming the path) when the file cannot be written,
    and :class:`InputError` when ``path`` is an input of the running command (or lies
    inside an input directory).
    """
    path = os.fspath(path)
    if not path:
        raise FileWriteError('""', 'empty output path')
    _check_guard(path, backup)
    shown = path
    if os.path.islink(path):  # write through the link: it keeps pointing at the new data
        path = os.path.realpath(path)
    info = _existing_target(path, shown)
    directory = os.path.dirname(os.path.abspath(path))
    tmp = None
    try:
        if not os.path.isdir(directory):
            os.makedirs(directory, exist_ok=True)
        remove_stale_temp_files(path)
        mode = stat.S_IMODE(info.st_mode) if info is not None else 0o666 & ~_umask()
        tmp = _write_file(path, data, mode)
        if backup and _existing_target(path, shown) is not None:
            _keep_backup(path)
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        reason = exc.strerror or str(exc)
        where = exc.filename if exc.filename and os.fspath(exc.filename) != path and \
            not str(exc.filename).endswith(TEMP_SUFFIX) else None
        raise FileWriteError(shown, f'cannot write: {reason}'
                             + (f' ({where})' if where else '')) from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_text_atomic(path: PathLike, text: str, backup: bool = False) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (see :func:`write_bytes_atomic`)."""
    write_bytes_atomic(path, text.encode('utf-8'), backup=backup)


def write_with_atomic(path: PathLike, writer: Callable[[IO[Any]], object], backup: bool = False,
                      binary: bool = False) -> None:
    """
    Call ``writer(handle)`` on an in-memory buffer, then write it atomically.

    For writers that need a file object (numpy, csv, OpenCV encoders): nothing reaches
    ``path`` unless ``writer`` returns without raising.
    """
    if binary:
        raw = io.BytesIO()
        writer(raw)
        data = raw.getvalue()
    else:
        text = io.StringIO()
        writer(text)
        data = text.getvalue().encode('utf-8')
    write_bytes_atomic(path, data, backup=backup)


@contextlib.contextmanager
def atomic_output_path(path: PathLike) -> Iterator[str]:
    """
    Yield a temporary path beside ``path`` to stream a large file into; commit it on exit.

    For writers that open the file themselves and write it in chunks (LAS/LAZ): memory
    stays bounded by the writer's chunk, and the target appears only once the block ends
    without an exception (fsync'ed, then ``os.replace``, keeping an existing file's mode).
    Failures are :class:`FileWriteError` naming ``path``; inputs are guarded as for
    :func:`write_bytes_atomic`.
    """
    path = os.fspath(path)
    if not path:
        raise FileWriteError('""', 'empty output path')
    _check_guard(path)
    if os.path.isdir(path):
        raise FileWriteError(path, 'is a directory; give a file name')
    shown = path
    if os.path.islink(path):
        path = os.path.realpath(path)
    tmp = None
    try:
        directory = os.path.dirname(os.path.abspath(path))
        os.makedirs(directory, exist_ok=True)
        remove_stale_temp_files(path)
        try:
            mode = stat.S_IMODE(os.stat(path).st_mode)
        except FileNotFoundError:
            mode = 0o666 & ~_umask()
        tmp = _write_file(path, b'', mode)
    except OSError as exc:
        raise FileWriteError(shown, f'cannot write: {exc.strerror or exc}') from None
    try:
        yield tmp
        with open(tmp, 'rb+') as handle:
            os.fsync(handle.fileno())
        os.replace(tmp, path)
        tmp = None
    except OSError as exc:
        raise FileWriteError(shown, f'cannot write: {exc.strerror or exc}') from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
