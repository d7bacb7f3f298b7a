"""Inputs that used to give silent wrong results: mismatched calibration, NaN files."""
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import calibrate_boresight, rotation_angle_deg
from accelcal_ros.lidar.calibrate_dir import report_lines
from accelcal_ros.sensor.model import SensorModel
import pytest

TRUTH = sim.default_boresight()


@pytest.fixture(scope='module')
def distorted_protocol():
    """Paper B's protocol read by an accelerometer with scale and bias errors."""
    true_model = SensorModel([1.02, 0.98, 1.01], [0.02, -0.015, 0.01], [0.0, 0.0, 0.0])
    return true_model, sim.simulate_protocol(TRUTH, seed=8, imu_model=true_model,
                                             still_s=3.0)


def test_mismatched_calibration_is_reported(distorted_protocol):
    """Another sensor's calibration: |g| off 1 g is named per position with advice."""
    true_model, protocol = distorted_protocol
    wrong = SensorModel([0.93, 1.06, 1.04], [0.05, -0.04, 0.06], [0.0, 0.0, 0.0])
    res = calibrate_boresight(sim.positions_for_calibration(protocol, wrong),
                              sim.nominal_mount())
    text = '\n'.join(report_lines(res))
    assert 'warning: the accelerometer calibration does not fit' in text
    assert 'check that the calibration file' in text and 'pos01' in text
    good = calibrate_boresight(sim.positions_for_calibration(protocol, true_model),
                               sim.nominal_mount())
    assert not any('calibration does not fit' in w for w in good.warnings)
    assert rotation_angle_deg(good.rotation, TRUTH) < 0.05
    # without a calibration nothing is claimed about |g|
    raw = calibrate_boresight(sim.positions_for_calibration(protocol), sim.nominal_mount())
    assert not any('calibration does not fit' in w for w in raw.warnings)
