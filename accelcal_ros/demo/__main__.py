"""
``python -m accelcal_ros.demo``: run the demo stages on simulated sensors.

Each stage starts the installed node executables as processes (as ``ros2 run`` does),
drives them through a probe node (as ``ros2 service call`` / ``ros2 topic echo`` do) and
prints a live readout. Outputs (calibration file, panorama, clouds, plots) go to
``--out`` (default ``demo_output/``).
"""
import argparse
import importlib
import importlib.util
import os
import sys
import time

from graph_harness.domain import allocate_domain_id

STAGES = ('driver', 'calibration', 'panorama', 'p2p', 'lidar')


class DemoContext:
    """What a stage gets: the graph (probe + launcher), the output folder, the options."""

    def __init__(self, graph, out_dir, quick):
        self.graph = graph
        self.out_dir = out_dir
        self.quick = quick

    def say(self, text):
        """Print one line of the readout immediately."""
        print(text, flush=True)


def available_stages():
    """Return the stages of :data:`STAGES` whose module is installed, in order."""
    return [s for s in STAGES
            if importlib.util.find_spec(f'accelcal_ros.demo.{s}_stage') is not None]


def main(argv=None):
    """Run the selected stages; returns the exit status."""
    parser = argparse.ArgumentParser(prog='run-demo', description=__doc__.splitlines()[0])
    parser.add_argument('--stages', default=','.join(available_stages()),
                        help=f'comma-separated stages to run, in order (default: all of '
                             f'{",".join(STAGES)})')
    parser.add_argument('--out', default='demo_output', help='output folder')
    parser.add_argument('--quick', action='store_true', help='shorter runs')
    args = parser.parse_args(argv)
    stages = [s.strip() for s in args.stages.split(',') if s.strip()]
    unknown = [s for s in stages if s not in STAGES]
    if unknown:
        parser.error(f'unknown stage(s) {unknown}; choose from {", ".join(STAGES)}')
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    lease = None
    if 'ROS_DOMAIN_ID' not in os.environ:  # keep off other graphs on this machine
        lease = allocate_domain_id()
        os.environ['ROS_DOMAIN_ID'] = str(lease.domain_id)
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]} (export it in another shell to '
          'watch, e.g. ros2 topic echo /attitude); outputs in '
          f'{os.path.abspath(args.out)}', flush=True)
    os.makedirs(args.out, exist_ok=True)
    from graph_harness.graph import Graph

    failed = []
    for stage in stages:
        module = importlib.import_module(f'accelcal_ros.demo.{stage}_stage')
        print(f'\n=== {stage} ===', flush=True)
        log_dir = os.path.join(args.out, 'logs', stage)
        os.makedirs(log_dir, exist_ok=True)
        graph = Graph(log_dir=log_dir, name='demo_probe')
        start = time.monotonic()
        try:
            module.run(DemoContext(graph, args.out, args.quick))
        except Exception as exc:  # a stage failing must not hide the others
            failed.append(stage)
            print(f'[{stage}] FAILED: {type(exc).__name__}: {exc} (logs: {log_dir})',
                  flush=True)
        finally:
            graph.close()
        print(f'[{stage}] {time.monotonic() - start:.1f} s', flush=True)
    print(f'\noutputs in {os.path.abspath(args.out)}'
          + (f'; failed stages: {", ".join(failed)}' if failed else ''), flush=True)
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
