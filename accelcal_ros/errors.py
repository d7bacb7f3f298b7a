"""
Exceptions raised by accelcal_ros.

Every error a user can cause (bad file, bad parameter, bad geometry, bad device) is an
:class:`AccelcalError`, so command-line tools and nodes can catch one type and show its
message, which always says what was wrong and, where possible, what to do.
"""
import os
from typing import Optional, Sequence, Union

PathLike = Union[str, 'os.PathLike[str]']
LISTED_NAMES = 5
"""Names a message lists (unknown keys or columns, repeated names); the rest are counted:
a text file read as YAML had one "key" a line (``/etc/shadow`` as a calibration file:
several kB of reason), a CSV header of 10^6 columns a 10.9 MB error line."""


def listed(names: Sequence[str]) -> str:
    """Return ``names`` for a message: the first :data:`LISTED_NAMES`, 40 characters each."""
    shown = [n if len(n) <= 40 else n[:37] + '...' for n in names[:LISTED_NAMES]]
    more = len(names) - len(shown)
    return ', '.join(shown) + (f' and {more} more' if more else '')


class AccelcalError(Exception):
    """Base class of all errors this package raises on purpose."""


class InputError(AccelcalError, ValueError):
    """A value given by the user or a message is invalid (NaN, wrong shape, range)."""


class FileFormatError(AccelcalError):
    """A file is missing, truncated or malformed; names the file and, if known, the line."""

    def __init__(self, path: PathLike, message: str, line: Optional[int] = None) -> None:
        self.path = str(path)
        self.line = line
        self.reason = message
        where = self.path if line is None else f'{self.path}:{line}'
        super().__init__(f'{where}: {message}')


class DeviceError(AccelcalError):
    """The sensor cannot be reached or is not what it should be (bus, address, ID)."""


class CalibrationError(AccelcalError):
    """A calibration cannot be computed or trusted (too few or badly spread positions)."""


class GeometryError(AccelcalError):
    """A geometric problem is degenerate or has no valid solution."""


class FileWriteError(AccelcalError):
    """An output file cannot be written (read-only place, a directory, no room); names it."""

    def __init__(self, path: PathLike, message: str) -> None:
        self.path = str(path)
        self.reason = message
        super().__init__(f'{self.path}: {message}')
