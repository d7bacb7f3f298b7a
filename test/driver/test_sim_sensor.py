"""The simulated ADXL345: truth model, datasheet noise, quantisation, schedule."""
from accelcal_ros.driver.sim_sensor import (near_uniform_poses_deg, poses_from_flat_list,
                                            SimulatedAdxl345)
from accelcal_ros.errors import InputError
from accelcal_ros.frames import roll_pitch_from_specific_force, specific_force_from_roll_pitch
from accelcal_ros.sensor.datasheet import datasheet_noise_std_g, FULL_RES_G_PER_LSB
from accelcal_ros.sensor.model import paper_a_model
import numpy as np
import pytest


def test_noise_matches_datasheet_and_readings_are_quantised():
    """Still sensor: std per axis within 5 % of the datasheet; values on the LSB grid."""
    sensor = SimulatedAdxl345(rate_hz=100.0, poses_deg=[[0.0, 0.0]], dwell_s=1000.0, seed=3)
    t = np.arange(20000) / 100.0
    readings = sensor.read(t)
    expected = datasheet_noise_std_g(100.0)
    assert readings.std(axis=0) == pytest.approx(expected, rel=0.05)
    assert np.allclose(readings / FULL_RES_G_PER_LSB, np.round(readings / FULL_RES_G_PER_LSB))
    # mean = truth model K f + b for a level sensor (f = [0, 0, 1])
    truth = paper_a_model(500)
    assert readings.mean(axis=0) == pytest.approx(truth.distort([0.0, 0.0, 1.0]), abs=3e-4)


def test_deterministic_for_a_seed():
    """The same seed gives the same samples; another seed does not."""
    t = np.arange(100) / 100.0
    a = SimulatedAdxl345(seed=7).read(t)
    b = SimulatedAdxl345(seed=7).read(t)
    c = SimulatedAdxl345(seed=8).read(t)
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_schedule_dwells_and_moves_smoothly():
    """Attitude equals each pose during its dwell and moves continuously between them."""
    poses = [[10.0, 20.0], [-30.0, 45.0], [170.0, -60.0]]
    sensor = SimulatedAdxl345(poses_deg=poses, dwell_s=2.0, move_s=1.0)
    for k, (roll, pitch) in enumerate(poses):
        r, p = sensor.attitude_at([3.0 * k + 0.5, 3.0 * k + 1.9])
        assert np.degrees(r) == pytest.approx([roll, roll]) and \
            np.degrees(p) == pytest.approx([pitch, pitch])
    assert list(sensor.pose_index([0.5, 2.5, 3.5])) == [0, -1, 1]
    t = np.linspace(2.0, 3.0, 201)
    f = specific_force_from_roll_pitch(*sensor.attitude_at(t))
    steps = np.degrees(np.arccos(np.clip(np.sum(f[1:] * f[:-1], axis=1), -1, 1)))
    assert steps.max() < 1.0  # no jump
    r, p = roll_pitch_from_specific_force(f[[0, -1]])
    assert np.degrees(p) == pytest.approx([20.0, 45.0], abs=1e-6)


def test_builtin_poses_cover_the_sphere():
    """The 24 built-in orientations spread gravity over the whole sphere."""
    poses = near_uniform_poses_deg(24)
    f = specific_force_from_roll_pitch(*np.radians(poses.T))
    cos = f @ f.T - 2 * np.eye(24)
    nearest = np.degrees(np.arccos(cos.max(axis=1)))
    assert nearest.min() > 25.0 and nearest.max() < 50.0
    assert np.linalg.norm(f.mean(axis=0)) < 0.05
    assert poses_from_flat_list([]).shape == (24, 2)
    with pytest.raises(InputError, match='pairs'):
        poses_from_flat_list([1.0, 2.0, 3.0])
    with pytest.raises(InputError, match='range_g'):
        SimulatedAdxl345(range_g=3)
