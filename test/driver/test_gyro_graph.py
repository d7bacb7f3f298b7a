"""imu_driver with the GY-85's ITG-3205 (simulated) -> attitude, gyro-aided, in a graph."""
import time

from accelcal_ros.driver.gyro_source import SIM_BIAS_RAD_S
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import Imu

pytestmark = pytest.mark.graph


def test_sim_itg3205_angular_velocity_reaches_the_attitude_node(graph):
    deep = QoSProfile(depth=2000, reliability=ReliabilityPolicy.BEST_EFFORT)
    raw = graph.collect(Imu, 'imu/data_raw', deep)
    diagnostics = graph.collect(DiagnosticArray, '/diagnostics', 50)
    graph.start('imu_driver', {'backend': 'sim', 'rate_hz': 100.0, 'gyro': 'itg3205',
                               'sim.poses_deg': [5.0, -3.0], 'sim.dwell_s': 3600.0})
    proc = graph.start('attitude', {'calibration.scale': list(PAPER_K500_SCALE),
                                    'calibration.bias': list(PAPER_K500_BIAS),
                                    'calibration.model': 'diagonal'})
    msgs = raw.wait_for(150, timeout=30.0)
    assert all(m.angular_velocity_covariance[0] > 0 for m in msgs[-100:])
    rates = np.array([[m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z]
                      for m in msgs[-100:]])
    # still: the simulated gyro reads its bias (ITG-3205 noise 0.0066 rad/s, 1 LSB 0.0012)
    np.testing.assert_allclose(rates.mean(axis=0), SIM_BIAS_RAD_S, atol=0.004)
    deadline = time.monotonic() + 30.0
    mode = values = None
    while time.monotonic() < deadline:
        for array in diagnostics.snapshot()[0]:   # in order: the newest status wins
            for status in array.status:
                kv = {k.key: k.value for k in status.values}
                if status.name.startswith('attitude') and 'mode' in kv:
                    mode, values = kv['mode'], kv
                elif status.name.startswith('imu_driver'):
                    assert kv.get('gyro') == 'itg3205' and kv.get('gyro_errors') == '0'
        if mode == 'gyro-aided':
            break
        time.sleep(0.3)
    assert mode == 'gyro-aided', (values, proc.output())
    bias = [float(v) for v in values['gyro_bias_rad_s'].split(',')]
    np.testing.assert_allclose(bias, SIM_BIAS_RAD_S, atol=0.004)
