"""
``accelcal``: the offline command line, usable on recorded data without a ROS graph.

Each feature registers its subcommands from its own ``cli.py`` module (listed in
:data:`FEATURE_CLI_MODULES`) through ``register(subparsers, study_subparsers)``; a module
keeps heavy imports inside its handlers so ``accelcal --help`` stays quick. A handler
returns an exit status. :class:`~accelcal_ros.errors.AccelcalError` is shown as one line
``accelcal: error: ...`` with status 2; nothing is written when a command fails.
"""
import argparse
import importlib
import sys

from accelcal_ros.errors import AccelcalError

FEATURE_CLI_MODULES = (
    'accelcal_ros.driver.cli',
    'accelcal_ros.calibration.cli',
    'accelcal_ros.panorama.cli',
    'accelcal_ros.p2p.cli',
    'accelcal_ros.lidar.cli',
)


def build_parser():
    """Build the full argument parser with every feature's subcommands."""
    parser = argparse.ArgumentParser(
        prog='accelcal',
        description='ADXL345 field calibration, attitude, panorama stitching, P2P '
                    'positioning and LiDAR-IMU boresight calibration on recorded data.')
    sub = parser.add_subparsers(dest='command', metavar='COMMAND')
    sub.required = True
    study = sub.add_parser('study', help='accuracy studies against ground truth and the papers')
    study_sub = study.add_subparsers(dest='study', metavar='STUDY')
    study_sub.required = True
    for name in FEATURE_CLI_MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as exc:
            if not exc.name or not name.startswith(exc.name):
                raise  # a dependency is missing, not the feature itself
            continue
        module.register(sub, study_sub)
    return parser


def main(argv=None):
    """Entry point of ``accelcal``; returns the exit status."""
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.handler(args) or 0)
    except AccelcalError as exc:
        print(f'accelcal: error: {exc}', file=sys.stderr)
        return 2
    except BrokenPipeError:
        return 0


if __name__ == '__main__':
    sys.exit(main())
