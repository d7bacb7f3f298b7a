"""
Where the nodes write their results: one default directory, and checks of output paths.

Every node output (calibration file, rig file, boresight, capture folders) defaults to a
path under :data:`DEFAULT_OUTPUT_DIR` (``~/.ros/accelcal/``, the place ROS 2 tools keep
per-user state), created on demand by the atomic writers. An output parameter is checked
when it is given (at start-up and at run time): not empty, the right extension, not a
directory, and a parent that is a directory or can be made one.
"""
import os
from typing import Optional, Sequence

from accelcal_ros.errors import InputError

DEFAULT_OUTPUT_DIR = os.path.join('~', '.ros', 'accelcal')
"""Default directory of every node output (``~`` expanded where written)."""
PNG_SUFFIXES = ('.png',)
"""What a plot is written as (PNG, whatever the name says): its outputs must say so."""


def default_output(name: str) -> str:
    """Return ``~/.ros/accelcal/<name>`` (unexpanded, as a parameter default shows it)."""
    return os.path.join(DEFAULT_OUTPUT_DIR, name)


def output_path_problem(value: str, suffixes: Sequence[str] = (),
                        directory: bool = False) -> Optional[str]:
    """
    Return why ``value`` cannot be an output path, or None when it can.

    ``suffixes`` (e.g. ``('.yaml', '.yml')``) are the accepted extensions (any when
    empty); ``directory`` says the output is a directory. Nothing is created.
    """
    if not value.strip():
        return 'must not be empty'
    if not directory:  # a device, FIFO or socket is never replaced (fileio's rule)
        from accelcal_ros.filecheck import existing_output_problem

        problem = existing_output_problem(value)
        if problem:
            return problem
    path = os.path.abspath(os.path.expanduser(value))
    if suffixes and not directory and not path.lower().endswith(tuple(suffixes)):
        return f'{value!r} must end with {" or ".join(suffixes)}'
    if os.path.isdir(path) and not directory:
        return f'{value!r} is a directory: give a file path'
    if os.path.exists(path) and directory and not os.path.isdir(path):
        return f'{value!r} is a file: give a directory'
    return parent_problem(value)


def parent_problem(value: str) -> Optional[str]:
    """
    Return why nothing can be made at ``value`` for want of a place, or None.

    Its nearest existing parent must be a directory this process may create entries in
    (the missing ones between are made by the atomic writers). Nothing is created.
    """
    parent = os.path.dirname(os.path.abspath(os.path.expanduser(value)))
    while parent and not os.path.exists(parent):
        parent = os.path.dirname(parent) if os.path.dirname(parent) != parent else ''
    if parent and not os.path.isdir(parent):
        return f'{value!r}: {parent} is a file, not a directory'
    if parent and not os.access(parent, os.W_OK | os.X_OK):
        return f'{value!r}: cannot create anything in {parent} (permission denied)'
    return None


def check_output_path(value: str, option: str, suffixes: Sequence[str] = (),
                      directory: bool = False) -> None:
    """
    Raise :class:`InputError` naming ``option`` when ``value`` cannot be that output.

    For a command's output options, checked before any work (see
    :func:`output_path_problem`): e.g. ``-o plot.txt`` of a PNG writer is refused with
    the extensions it can write.
    """
    problem = output_path_problem(value, suffixes, directory)
    if problem:
        raise InputError(f'{option} {problem}')


def output_validator(suffixes: Sequence[str] = (), directory: bool = False):
    """Return a ParamSpec validator that applies :func:`output_path_problem`."""
    def check(value: str) -> Optional[str]:
        return output_path_problem(value, suffixes, directory)
    return check
