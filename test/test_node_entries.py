"""
The node executables start through :mod:`accelcal_ros.nodes`: OpenBLAS in one thread.

A child process loads numpy and OpenCV after :func:`prepare_node_process` and asks every
OpenBLAS it loaded for its thread count (``openblas_get_num_threads`` under the names the
wheels and Debian give it); ``benchmarks/bench_blas_threads.py`` measures what the
threads cost.
"""
import ast
import os
import subprocess
import sys

from accelcal_ros import nodes
import pytest

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CHILD = r"""
import ctypes, json, sys
if sys.argv[1] == 'prepare':
    from accelcal_ros.nodes import prepare_node_process
    assert prepare_node_process()
import numpy, cv2
numpy.ones((4, 3)) @ numpy.eye(3)
counts = {}
for path in sorted({line.split()[-1] for line in open('/proc/self/maps')
                    if 'openblas' in line.lower() and '.so' in line}):
    lib = ctypes.CDLL(path)
    for name in ('openblas_get_num_threads', 'openblas_get_num_threads64_',
                 'scipy_openblas_get_num_threads64_', 'scipy_openblas_get_num_threads'):
        if hasattr(lib, name):
            counts[path] = getattr(lib, name)()
            break
print(json.dumps(counts))
"""


def _blas_threads(mode, **env):
    base = {k: v for k, v in os.environ.items() if k != nodes.BLAS_THREADS_VARIABLE}
    done = subprocess.run([sys.executable, '-c', CHILD, mode], env=dict(base, **env),
                          capture_output=True, text=True, check=True)
    import json

    return json.loads(done.stdout.splitlines()[-1])


def _console_scripts():
    with open(os.path.join(REPO, 'setup.py'), encoding='utf-8') as handle:
        tree = ast.parse(handle.read())
    for item in ast.walk(tree):
        if isinstance(item, ast.Dict):
            for key, value in zip(item.keys, item.values):
                if isinstance(key, ast.Constant) and key.value == 'console_scripts':
                    return dict(line.replace(' ', '').split('=')
                                for line in ast.literal_eval(value))
    raise AssertionError('no console_scripts in setup.py')


def test_every_node_executable_starts_through_the_nodes_module():
    """setup.py's node executables are accelcal_ros.nodes' functions, each a node's main."""
    scripts = _console_scripts()
    assert scripts.pop('accelcal') == 'accelcal_ros.cli:main'
    assert set(scripts) == set(nodes.NODE_MODULES)
    import importlib

    for name, target in scripts.items():
        assert target == f'accelcal_ros.nodes:{name}'
        assert callable(getattr(nodes, name))
        assert callable(importlib.import_module(nodes.NODE_MODULES[name]).main)


def test_a_node_process_loads_openblas_with_one_thread():
    """After prepare_node_process every OpenBLAS has 1 thread; without it, one per core."""
    prepared = _blas_threads('prepare')
    assert prepared and set(prepared.values()) == {1}, prepared
    if len(os.sched_getaffinity(0)) > 1:  # the check can fail: without it numpy's has more
        assert max(_blas_threads('plain').values()) > 1


@pytest.mark.parametrize('value', ['2', '1'])
def test_a_thread_count_the_environment_sets_is_kept(value):
    """OPENBLAS_NUM_THREADS given by the user wins over the node's default."""
    counts = _blas_threads('prepare', OPENBLAS_NUM_THREADS=value)
    assert max(counts.values()) == int(value), counts  # (OpenCV 4.6's OpenBLAS 0.3.3: 1)
