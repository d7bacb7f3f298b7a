"""
``accelcal``: the offline command line, usable on recorded data without a ROS graph.

Each feature registers its subcommands from its own ``cli.py`` module (listed in
:data:`FEATURE_CLI_MODULES`) through ``register(subparsers, study_subparsers)``; a module
keeps heavy imports inside its handlers so ``accelcal --help`` stays quick. A handler
returns an exit status. Numeric options use the argument types of
:mod:`accelcal_ros.cli_args`, so an out-of-range value is a usage error (status 2).

Errors are one line on stderr, never a traceback: an
:class:`~accelcal_ros.errors.AccelcalError` (bad file, bad value, failed write) is shown as
``accelcal: error: ...`` with status 1; anything unexpected as ``accelcal: internal
error: ...`` with status 1 and a hint (``ACCELCAL_DEBUG=1`` shows the traceback). Every
command runs inside :func:`accelcal_ros.fileio.guard_inputs`: it cannot write over a file
it reads.
"""
import argparse
import importlib
import os
import sys
from typing import Any, List, NoReturn, Optional, Sequence, Tuple

from accelcal_ros.errors import AccelcalError, InputError

FEATURE_CLI_MODULES = (
    'accelcal_ros.driver.cli',
    'accelcal_ros.calibration.cli',
    'accelcal_ros.attitude.cli',
    'accelcal_ros.panorama.cli',
    'accelcal_ros.p2p.cli',
    'accelcal_ros.lidar.cli',
    'accelcal_ros.rig.cli',
)

#: argument names (``dest``) that are outputs (also any ``output_*``, ``*_output``,
#: ``out_*``, ``*_out``, ``*_plot``); every other argument naming an existing file is an
#: input the command must not overwrite
OUTPUT_DESTS = frozenset({'output', 'plot', 'json', 'out', 'out_dir', 'output_dir'})


#: output arguments (``dest``) that always name a file, never a folder: a plot, a JSON
#: table (also any ``*_plot``). A command names its other file-only outputs with
#: ``set_defaults(file_outputs=frozenset({...}))``; ``-o`` is a folder for some commands
#: (a rosbag2, a folder of frames), so it is file-only only where a command says so
FILE_OUTPUT_DESTS = frozenset({'plot', 'json'})


def is_output_dest(dest: str) -> bool:
    """Return whether an argument (by its ``dest``) names something the command writes."""
    return (dest in OUTPUT_DESTS or dest.startswith(('output_', 'out_'))
            or dest.endswith(('_output', '_out', '_plot')))


def is_file_output(dest: str, args: argparse.Namespace) -> bool:
    """Return whether the output argument ``dest`` of a parsed command is never a folder."""
    return (dest in FILE_OUTPUT_DESTS or dest.endswith('_plot')
            or dest in getattr(args, 'file_outputs', ()))


EPILOG = ('Errors are printed as one line and exit with status 1 (2 for a bad command '
          'line). Set ACCELCAL_DEBUG=1 to see the Python traceback of an unexpected error. '
          'No command writes over one of its input files.')


def fit_package_calibrations(count: int, seed: int = 0) -> list:
    """
    Return the package's own K = 12 calibrations for the studies (``args.fit_calibrations``).

    ``count`` independent LM fits of 12 recommended positions x 1 s at 100 Hz of the
    simulated sensor (:func:`accelcal_ros.calibration.study.fitted_models`). The panorama
    and P2P studies compare them with paper A's sets; they get this function from the
    dispatcher because features never import each other.
    """
    from accelcal_ros.calibration.study import fitted_models

    return list(fitted_models(positions=12, seconds_per_position=1.0, count=count, seed=seed,
                              layout='recommended', model='full'))


def panorama_horizon_errors(true_rp: Any, estimates: Any, label: str = '') -> dict:
    """
    Return the panorama's horizon errors through a drive (``args.panorama_horizon``).

    ``true_rp`` ``(N, 2)`` and ``estimates`` ``{name: (N, 2)}`` (roll, pitch in rad at the
    frame times): :func:`accelcal_ros.panorama.horizon_track.drive_horizon_errors`, plus
    its table under ``'table'``. ``accelcal study motion`` (attitude feature) gets it from
    the dispatcher because features never import each other.
    """
    from accelcal_ros.panorama.horizon_track import drive_horizon_errors, format_drive_horizon
    from accelcal_ros.recording.progress import track

    result = drive_horizon_errors(true_rp, estimates, progress=track)
    result['table'] = format_drive_horizon(result, label)
    return result


class _Parser(argparse.ArgumentParser):
    """An argument parser whose usage errors are one line (status 2)."""

    def error(self, message: str) -> NoReturn:
        """Print ``accelcal: error: MESSAGE`` and where the usage is; exit with status 2."""
        self.exit(2, f'accelcal: error: {" ".join(message.split())} ({self.prog} --help '
                     'shows the usage)\n')


def build_parser() -> argparse.ArgumentParser:
    """Build the full argument parser with every feature's subcommands."""
    parser = _Parser(
        prog='accelcal',
        description='ADXL345 field calibration, attitude, panorama stitching, P2P '
                    'positioning and LiDAR-IMU boresight calibration on recorded data.',
        epilog=EPILOG)
    parser.set_defaults(fit_calibrations=fit_package_calibrations,
                        panorama_horizon=panorama_horizon_errors)
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    sub.required = True
    study = sub.add_parser('study', help='accuracy studies against ground truth and the papers')
    study_sub = study.add_subparsers(dest='study', metavar='STUDY')
    study_sub.required = True
    sample = sub.add_parser('sample-data', help='write the simulated recordings the '
                            "README's commands use (bags, CSV, PCD, images) into DIR")
    sample.add_argument('out_dir', metavar='DIR', help='directory to write into (created)')
    sample.add_argument('--only', nargs='+', metavar='JOURNEY',
                        choices=[name for name, _ in _sample_journeys()],
                        help='write only these journeys (default: all)')
    sample.set_defaults(handler=_sample_data)
    for name in FEATURE_CLI_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if not exc.name or not name.startswith(exc.name):
                raise  # a dependency is missing, not the feature itself
            continue
        module.register(sub, study_sub)
    return parser


def _sample_journeys():
    from accelcal_ros.sample_data import JOURNEYS

    return JOURNEYS


def _sample_data(args: argparse.Namespace) -> int:
    from accelcal_ros.sample_data import write_sample_data

    written = write_sample_data(args.out_dir, args.only)
    print(f'wrote {len(written)} sample recordings to {args.out_dir}: {", ".join(written)}')
    return 0


def input_paths(args: argparse.Namespace) -> List[str]:
    """
    Return the arguments of a parsed command that name existing inputs (not outputs).

    Files and non-empty directories (a bag, a data set): the command may write neither
    over them nor inside them.
    """
    paths = []
    for dest, value in vars(args).items():
        if is_output_dest(dest):
            continue
        for item in (value if isinstance(value, (list, tuple)) else [value]):
            if isinstance(item, (str, os.PathLike)) and item and _holds_input(item):
                paths.append(os.fspath(item))
    return paths


def _holds_input(path: 'str | os.PathLike[str]') -> bool:
    """Return whether ``path`` is a file or a non-empty directory (a bag, a data set)."""
    if os.path.isdir(path):
        try:
            return bool(os.listdir(path))
        except OSError:
            return False
    return os.path.exists(path)


def output_arguments(args: argparse.Namespace) -> List[Tuple[str, str]]:
    """Return ``(dest, path)`` of the output arguments of a parsed command that are set."""
    return [(dest, os.fspath(v)) for dest, v in vars(args).items()
            if is_output_dest(dest) and isinstance(v, (str, os.PathLike)) and v]


def output_problem(dest: str, path: str, args: argparse.Namespace) -> Optional[str]:
    """
    Return why the output ``path`` (argument ``dest``) cannot be written, or None.

    A device, a FIFO or a socket is never an output; an existing directory is refused
    for a file-only output (:func:`is_file_output`) and left to the command otherwise
    (a rosbag2 or a folder of frames is a directory); a new path needs a parent it can be
    made in (:func:`~accelcal_ros.outputs.parent_problem`: a file there, or no permission,
    is refused now, not after the command's work).
    """
    from accelcal_ros.filecheck import existing_output_problem
    from accelcal_ros.outputs import parent_problem

    if path == '-':   # wrote a file named "-"
        return "'-': standard output is not an output here; give a file path"
    if os.path.isdir(path):
        return existing_output_problem(path) if is_file_output(dest, args) else None
    problem = existing_output_problem(path)
    return f'{problem}; give a file path' if problem else parent_problem(path)


def run_command(args: argparse.Namespace) -> int:
    """Run a parsed command: inputs guarded, every output checked before any work."""
    from accelcal_ros.fileio import guard_inputs, refuse_overwriting_inputs

    inputs = input_paths(args)
    arguments = output_arguments(args)
    outputs = [path for _, path in arguments]
    for k, (dest, output) in enumerate(arguments):
        refuse_overwriting_inputs(output, inputs)
        problem = output_problem(dest, output, args)
        if problem:  # a directory, /dev/null, a FIFO: refused before any work, not after it
            raise InputError(f'output {problem}')
        suffixes = getattr(args, 'output_suffixes', {}).get(dest)
        if suffixes and not output.lower().endswith(tuple(suffixes)):
            # `calibrate -o calib.png` wrote YAML; `boresight -o positions/pos16.ply` wrote
            # YAML where the next run read it as a scan
            raise InputError(f'output {output!r} must end with {" or ".join(suffixes)} '
                             f'(what this command writes)')
        if os.path.realpath(output) in (os.path.realpath(o) for o in outputs[:k]):
            raise InputError(f'{output} is given for two outputs; the second would overwrite '
                             'the first: give each output its own path')
    with guard_inputs(inputs):
        return int(args.handler(args) or 0)


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Entry point of ``accelcal``; returns the exit status (errors: one line on stderr)."""
    try:
        parser = build_parser()
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, or a usage error argparse has printed
        return exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    try:
        return run_command(args)
    except AccelcalError as exc:
        print(f'accelcal: error: {_one_line(exc)}', file=sys.stderr)
        return 1
    except BrokenPipeError:
        return 0
    except KeyboardInterrupt:
        print('accelcal: interrupted', file=sys.stderr)
        return 130
    except UnicodeDecodeError as exc:  # a text stream (stdin, --input) that is not UTF-8
        print(f'accelcal: error: input is not UTF-8 text (byte 0x{exc.object[exc.start]:02x} '
              f'at offset {exc.start} of a block); is this the right file?', file=sys.stderr)
        return 1
    except MemoryError as exc:  # numpy's 'Unable to allocate 2.5 GiB ...' (not a bug)
        print(f'accelcal: error: out of memory ({_one_line(exc)}); ask for a smaller output '
              'or fewer trials', file=sys.stderr)
        return 1
    except OSError as exc:
        where = f'{exc.filename}: ' if exc.filename else ''
        print(f'accelcal: error: {where}{exc.strerror or exc}', file=sys.stderr)
        return 1
    except Exception as exc:  # noqa: B902 - last resort: one line, never a traceback
        if os.environ.get('ACCELCAL_DEBUG') == '1':
            raise
        print(f'accelcal: internal error: {type(exc).__name__}: {_one_line(exc)} (this is a '
              'bug; run again with ACCELCAL_DEBUG=1 for the traceback and report it)',
              file=sys.stderr)
        return 1


def _one_line(exc):
    return ' '.join(str(exc).split()) or type(exc).__name__


if __name__ == '__main__':
    sys.exit(main())
