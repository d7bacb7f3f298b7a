"""
One source for every parameter: the ParamSpecs; config files and core defaults agree with them.

Pure (no ROS graph): the graph test ``test/rosutil/test_params_graph.py`` asks the running
nodes the same questions.
"""
import os
import re

from accelcal_ros.calibration.params import calibrator_config, CONFIG_FIELDS
from accelcal_ros.calibration.session import CalibratorConfig
from accelcal_ros.lidar.capture import CaptureSettings
from accelcal_ros.lidar.params import CAPTURE_FIELDS, capture_settings
from accelcal_ros.node_params import NODE_PARAMS, node_specs
import pytest
import yaml

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

_PYTHON_TYPES = {'bool': bool, 'int': int, 'double': float, 'string': str}


def _has_kind(value, kind):
    """Whether a YAML value has exactly the spec's type (no int where a double is declared)."""
    if kind.endswith('_array'):
        element = _PYTHON_TYPES[kind.split('_')[0]]
        return isinstance(value, list) and all(type(v) is element for v in value)
    return type(value) is _PYTHON_TYPES[kind]


def _executables():
    with open(os.path.join(REPO, 'setup.py')) as handle:
        text = handle.read()
    return sorted(set(re.findall(r"'(\w+) = accelcal_ros\.[\w.]+:\w+'", text)) - {'accelcal'})


def test_every_node_executable_has_its_param_specs():
    """A new node executable must be registered in accelcal_ros.node_params."""
    assert set(_executables()) == set(NODE_PARAMS)


@pytest.mark.parametrize('node', sorted(NODE_PARAMS))
def test_defaults_are_valid_values_of_their_declared_type(node):
    """Each default passes its own check unchanged and has the declared type."""
    for spec in node_specs(node):
        assert spec.check(spec.default) == (spec.default, None), spec.name
        assert _has_kind(spec.default, spec.kind), spec.name


@pytest.mark.parametrize('node', sorted(NODE_PARAMS))
def test_config_file_lists_every_parameter_with_its_type_and_default(node):
    """config/<node>.yaml: the node's section holds exactly the declared names and defaults."""
    with open(os.path.join(REPO, 'config', f'{node}.yaml')) as handle:
        document = yaml.safe_load(handle)
    assert list(document) == [node]
    values = document[node]['ros__parameters']
    specs = {s.name: s for s in node_specs(node)}
    assert sorted(values) == sorted(specs)
    for name, value in values.items():
        spec = specs[name]
        assert _has_kind(value, spec.kind), f'{node}.yaml {name}: {value!r} is not {spec.kind}'
        assert value == spec.default, f'{node}.yaml {name}: {value!r} != {spec.default!r}'


def test_core_config_defaults_are_the_spec_defaults():
    """The calibration session and the LiDAR capture take the specs' defaults unchanged."""
    calibration = {s.name: s.default for s in node_specs('calibration')}
    assert calibrator_config(calibration) == CalibratorConfig()
    assert set(CONFIG_FIELDS) <= set(calibration)
    lidar = {s.name: s.default for s in node_specs('lidar_calibration')}
    assert capture_settings(lidar) == CaptureSettings()
    assert set(CAPTURE_FIELDS) <= set(lidar)
    changed = capture_settings({'auto_capture': False, 'clouds_per_capture': 3})
    assert (changed.auto, changed.clouds_per_capture) == (False, 3)


UNBOUNDED = {('attitude', 'yaw_variance'): 'any finite variance says "yaw unknown" (REP-145)'}
"""Number parameters that may take any finite value, and why."""


@pytest.mark.parametrize('node', sorted(NODE_PARAMS))
def test_every_number_parameter_is_bounded(node):
    """
    A number no rig could have is refused with a reason, never used.

    ``calibration_frames`` took ``imu_mount_xyz_m = [1e308, 1e308, 1e308]`` and put it on
    /tf_static; ``lidar_calibration`` took the same lever arm and prior, ``cloud_assembler``
    a map origin of 1e308 m; a 9-value rotation of 1e308 overflowed numpy while checked.
    """
    import warnings

    for spec in node_specs(node):
        if not spec.kind.startswith(('double', 'int')) or (node, spec.name) in UNBOUNDED:
            continue
        big = 1e308 if spec.kind.startswith('double') else 2 ** 62
        length = max(spec.lengths or (3,)) or 3
        for sign in (1, -1):
            value = [sign * big] * length if spec.kind.endswith('_array') else sign * big
            with warnings.catch_warnings():
                warnings.simplefilter('error')
                _, reason = spec.check(value)
            assert reason and reason.startswith(spec.name), (spec.name, value)
