"""
What the offline commands share to take a bag where they take a recording.

:func:`add_stamp_argument` adds ``--stamp {header,receive}``; :func:`open_bag` opens a
:class:`~accelcal_ros.recording.bag.BagReader` and states what it noticed;
:func:`warn` prints ``accelcal: warning: ...`` lines on stderr; :func:`is_bag_output`
decides whether an output path names a bag (``*.bag``, ``*.mcap``, ``*.db3`` or a path
without a suffix, the rosbag2 directory) rather than a CSV.
"""
import argparse
import os
import sys
from typing import Iterable, Union

from accelcal_ros.recording.bag import BagReader

PathLike = Union[str, 'os.PathLike[str]']

__all__ = ['add_stamp_argument', 'is_bag_output', 'open_bag', 'warn']


def add_stamp_argument(parser: argparse.ArgumentParser) -> None:
    """Add ``--stamp`` (which time of a bag message is used)."""
    parser.add_argument('--stamp', choices=('header', 'receive'), default='header',
                        help='bags: time of a message: its header stamp (default; a zero '
                             'stamp falls back to the receive time) or the receive time the '
                             'bag stored')


def warn(lines: Iterable[str]) -> None:
    """Print each line as ``accelcal: warning: ...`` on stderr."""
    for line in lines:
        print(f'accelcal: warning: {line}', file=sys.stderr)


def open_bag(path: PathLike, stamp: str = 'header') -> BagReader:
    """Open a bag for a command; notes (e.g. missing metadata.yaml) go to stderr."""
    bag = BagReader(path, stamp=stamp)
    warn(bag.notes)
    return bag


def is_bag_output(path: PathLike) -> bool:
    """Return True when an output path names a bag rather than a CSV or image file."""
    text = os.fspath(path)
    suffix = os.path.splitext(text.rstrip('/'))[1].lower()
    return text.endswith('/') or suffix in ('.bag', '.mcap', '.db3', '')
