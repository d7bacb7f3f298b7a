"""
Parameters as ``ros2 param dump/get/set`` see them, on every node executable.

``ros2 param dump`` calls ListParameters, then GetParameters for every listed name: one
parameter without a value made rclpy answer nothing for the whole request. Each node is
started with its installed config file (``--params-file``), as the launch files do.
"""
import math
import os
import time

from accelcal_ros.node_params import NODE_PARAMS, node_specs
from accelcal_ros.rosutil.params import PARAMETER_TYPES
from accelcal_ros.rosutil.stamps import stamp_to_seconds
import pytest
from rcl_interfaces.msg import ParameterType
from rcl_interfaces.srv import (GetParameters, ListParameters, SetParameters,
                                SetParametersAtomically)
from rclpy.parameter import Parameter, parameter_value_to_python

pytestmark = pytest.mark.graph

G = 9.80665


def _share():
    return os.path.join(os.environ['ACCELCAL_INSTALL'], 'accelcal_ros', 'share',
                        'accelcal_ros')


def _start_overrides(node):
    """Values a node needs to start here (no I2C bus; the stitcher needs a rig)."""
    if node == 'imu_driver':
        return {'backend': 'sim'}
    if node == 'stitcher':
        return {'rig_file': os.path.join(_share(), 'config', 'rig_example.yaml'),
                'width': 360, 'height': 240, 'pipeline': False}
    return {}


def _call(graph, srv_type, name, request=None):
    """Call a parameter service (idempotent: sent again if its answer is lost)."""
    return graph.call(srv_type, name, request, timeout=40.0, resend_s=5.0)


def _set(graph, node, values):
    """Do what ``ros2 param set`` does; return the SetParametersResult list."""
    request = SetParameters.Request()
    request.parameters = [Parameter(k, value=v).to_parameter_msg() for k, v in values.items()]
    return _call(graph, SetParameters, f'/{node}/set_parameters', request).results


def _dump(graph, node):
    """Do what ``ros2 param dump`` does: return {name: (type, python value)}."""
    listed = _call(graph, ListParameters, f'/{node}/list_parameters')
    names = list(listed.result.names)
    request = GetParameters.Request()
    request.names = names
    answer = _call(graph, GetParameters, f'/{node}/get_parameters', request)
    assert len(answer.values) == len(names), f'{node}: GetParameters answered nothing'
    return {n: (v.type, parameter_value_to_python(v)) for n, v in zip(names, answer.values)}


def _same(value, expected):
    if isinstance(expected, float):
        return math.isclose(value, expected)
    if isinstance(expected, list):
        return len(value) == len(expected) and all(_same(a, b) for a, b in zip(value, expected))
    return value == expected


@pytest.mark.parametrize('node', sorted(NODE_PARAMS))
def test_every_parameter_has_a_value_of_its_declared_type(graph, node):
    """Every listed name is answered, with its declared type and expected value."""
    overrides = _start_overrides(node)
    config = os.path.join(_share(), 'config', f'{node}.yaml')
    graph.start(node, overrides, args=('--ros-args', '--params-file', config))
    dump = _dump(graph, node)
    assert all(kind != ParameterType.PARAMETER_NOT_SET for kind, _ in dump.values()), dump
    for spec in node_specs(node):
        assert spec.name in dump, f'{node} does not declare {spec.name}'
        kind, value = dump[spec.name]
        assert kind == PARAMETER_TYPES[spec.kind].value, f'{node} {spec.name}: type {kind}'
        expected = overrides.get(spec.name, spec.default)
        assert _same(value, expected), f'{node} {spec.name}: {value!r} != {expected!r}'


def test_numbers_are_coerced_to_the_declared_type_or_refused(graph):
    """``param set calibration.scale "[1, 1, 1]"`` / ``time_constant_s 2``: stay doubles."""
    graph.start('attitude')
    results = _set(graph, 'attitude', {'calibration.scale': [1, 2, 1], 'time_constant_s': 2,
                                       'noise_std_g': []})
    assert all(r.successful for r in results), [r.reason for r in results]
    refused = _set(graph, 'attitude', {'time_constant_s': 'fast', 'accel_threshold_g': [0.1]})
    assert not any(r.successful for r in refused)
    assert 'double' in refused[0].reason.lower()
    dump = _dump(graph, 'attitude')
    assert dump['calibration.scale'] == (ParameterType.PARAMETER_DOUBLE_ARRAY,
                                         [1.0, 2.0, 1.0])
    assert dump['time_constant_s'] == (ParameterType.PARAMETER_DOUBLE, 2.0)
    assert dump['accel_threshold_g'][0] == ParameterType.PARAMETER_DOUBLE
    assert dump['noise_std_g'] == (ParameterType.PARAMETER_DOUBLE_ARRAY, [])


def _pitch_of_level_sample(graph, pub, collector, stamp):
    from sensor_msgs.msg import Imu

    msg = Imu()
    msg.header.stamp.sec = stamp
    msg.linear_acceleration.z = G
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        pub.publish(msg)
        time.sleep(0.1)
        for out in collector.snapshot()[0]:
            if stamp_to_seconds(out.header.stamp) == stamp:
                return out.vector.y
    raise TimeoutError(f'no attitude for the sample stamped {stamp}')


def test_a_rejected_atomic_request_applies_nothing(graph, tmp_path):
    """Bias accepted, then a missing calibration file rejected: the bias is not applied."""
    from geometry_msgs.msg import Vector3Stamped
    from rclpy.qos import qos_profile_sensor_data
    from sensor_msgs.msg import Imu

    graph.start('attitude')
    pub = graph.node.create_publisher(Imu, 'imu/data_raw', qos_profile_sensor_data)
    attitude = graph.collect(Vector3Stamped, 'attitude')
    assert abs(_pitch_of_level_sample(graph, pub, attitude, 1)) < 1e-6

    request = SetParametersAtomically.Request()
    request.parameters = [
        Parameter('calibration.bias', value=[0.5, 0.0, 0.0]).to_parameter_msg(),
        Parameter('calibration_file', value=str(tmp_path / 'missing.yaml')).to_parameter_msg()]
    result = _call(graph, SetParametersAtomically, '/attitude/set_parameters_atomically',
                   request).result
    assert not result.successful and 'missing.yaml' in result.reason
    assert _dump(graph, 'attitude')['calibration.bias'][1] == [0.0, 0.0, 0.0]
    # with the bias applied, a level sample would read a pitch of atan(0.5) = 26.6 deg
    assert abs(_pitch_of_level_sample(graph, pub, attitude, 2)) < 1e-6

    request.parameters = request.parameters[:1]  # the same bias alone is applied
    result = _call(graph, SetParametersAtomically, '/attitude/set_parameters_atomically',
                   request).result
    assert result.successful
    assert math.degrees(_pitch_of_level_sample(graph, pub, attitude, 3)) == \
        pytest.approx(math.degrees(math.atan(0.5)), abs=0.01)
