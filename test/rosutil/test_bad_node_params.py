"""
Table-driven: every numeric parameter of every node, set out of its range at start-up.

Each case constructs the node class in this process with ``--ros-args -p name:=value``
(what ``ros2 run`` passes) and expects one :class:`InputError` naming the parameter,
raised before rclpy's own range check (which printed a 24-line traceback). The runner
turns that error into one FATAL line and exit status 1 (``test_runner_graph.py`` checks
that on the installed executable).
"""
import importlib
import json
import re

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.node_params import NODE_PARAMS, node_specs
from accelcal_ros.nodes import NODE_MODULES
from accelcal_ros.rosutil.runner import _node_in_traceback
import pytest
import rclpy
from rclpy.node import Node


def _node_classes():
    classes = {}
    for exe in NODE_PARAMS:  # the executables' node modules (setup.py -> accelcal_ros.nodes)
        module = importlib.import_module(NODE_MODULES[exe])
        found = [c for c in vars(module).values() if isinstance(c, type)
                 and issubclass(c, Node) and c.__module__ == module.__name__]
        assert len(found) == 1, (exe, found)
        classes[exe] = found[0]
    return classes


def _destroy(node):
    """
    Destroy the node (also one whose constructor raised, as the runner does) before shutdown.

    Left to the garbage collector, a half-built node was destroyed during a later case,
    after its context's shutdown and beside the later case's participant: Fast DDS's
    participant teardown then spun for ever in ``DomainParticipant::set_listener`` against
    a discovery callback of the same process (one hung ``./run-tests``, SIGTERM ignored).
    """
    if node is not None:
        try:
            node.destroy_node()
        except Exception:  # noqa: B902 - a node that failed before its handle existed
            pass


def _out_of_range(spec):
    """Return a value just outside the spec's range (below its minimum, else above its maximum)."""
    if spec.minimum is not None:
        bad = spec.minimum - 1
    else:
        bad = spec.maximum + 1
    element = float(bad) if spec.kind.startswith('double') else int(bad)
    if spec.kind.endswith('_array'):
        return [element] * (max(spec.lengths) if spec.lengths else 3)
    return element


CASES = [(exe, spec) for exe in sorted(NODE_PARAMS) for spec in node_specs(exe)
         if spec.kind.split('_')[0] in ('int', 'double')
         and (spec.minimum is not None or spec.maximum is not None)]


def test_the_table_is_not_empty():
    """Every node has numeric parameters with ranges."""
    assert {exe for exe, _ in CASES} == set(NODE_PARAMS)


@pytest.mark.parametrize('exe, spec', CASES, ids=[f'{e}-{s.name}' for e, s in CASES])
def test_out_of_range_start_value_is_one_input_error(exe, spec):
    """The error names the parameter and says which bound it breaks."""
    value = _out_of_range(spec)
    error = _start_error(exe, {spec.name: value})
    assert isinstance(error, InputError), f'{exe} started with {spec.name}:={value}: {error}'
    message = str(error)
    assert '\n' not in message
    assert f'{spec.name}: ' in message
    assert 'below the minimum' in message or 'above the maximum' in message


def _start_error(exe, params):
    """
    Construct ``exe``'s node with ``params`` given as ``-p``; return its error or None.

    An :class:`AccelcalError` (InputError, FileFormatError, ...): what the runner turns into
    one FATAL line and exit status 1.
    """
    args = ['test', '--ros-args']
    for name, value in params.items():
        args += ['-p', f'{name}:={json.dumps(value)}']
    rclpy.init(args=args)
    node = error = None
    try:
        node = _node_classes()[exe]()
    except AccelcalError as exc:
        error = exc
    finally:
        _destroy(node if node is not None else
                 _node_in_traceback(error) if error is not None else None)
        rclpy.shutdown()
    return error


@pytest.mark.parametrize('exe, params, words', [
    ('cloud_assembler', {'frame_id': 'bad frame id'}, 'frame_id.*not a valid frame id'),
    ('cloud_assembler', {'frame_id': '/map'}, 'leading "/"'),
    ('cloud_assembler', {'output_file': '/tmp/accelcal_never_written.laz'},
     'LAS/LAZ needs map_crs'),
    ('imu_driver', {'frame_id': ''}, 'frame_id: must not be empty'),
    ('stitcher', {'frame_id': ''}, 'frame_id.*non-empty'),
    ('stitcher', {'frame_id': 'pano rig'}, 'frame_id.*not a valid frame id'),
])
def test_bad_start_strings_are_one_input_error(exe, params, words):
    """A frame id or an output the node could never use stops it at start, with the reason."""
    error = _start_error(exe, params)
    assert error is not None, f'{exe} started with {params}'
    assert '\n' not in str(error)
    assert re.search(words, str(error)), str(error)


def test_a_bad_calibration_file_at_start_stops_attitude(tmp_path):
    """A calibration file that is not one stops the node (it ran uncalibrated, logging)."""
    bad = tmp_path / 'calib.yaml'
    bad.write_text('- not\n- a mapping\n')
    error = _start_error('attitude', {'calibration_file': str(bad)})
    assert error is not None and '\n' not in str(error)
    assert str(bad) in str(error) or 'calib.yaml' in str(error), str(error)
