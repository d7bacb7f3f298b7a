"""imu_to_camera and the board tilt from gravity, on exact synthetic poses."""
from accelcal_ros.errors import CalibrationError
from accelcal_ros.frames import rot_y
from accelcal_ros.rig.extrinsics import rotation_angle_deg
from accelcal_ros.rig.imu_to_camera import fit_imu_to_camera, heading_spread_deg
from accelcal_ros.rig.render import board_in_camera, default_truth, plan_poses, PoseTruth
import numpy as np
import pytest


def _inputs(truth, poses, noise_deg=0.0, seed=0):
    rng = np.random.default_rng(seed)
    boards, gravity = {}, {}
    for k, pose in enumerate(poses):
        name = f'pose{k:02d}'
        boards[name] = board_in_camera(truth, pose, 0)
        f = pose.specific_force + rng.normal(0.0, np.radians(noise_deg), 3)
        gravity[name] = 9.8 * f
    return boards, gravity


def test_recovers_mount_and_tilt_when_the_rig_turns():
    """Headings all round: imu_to_camera and a 0.4 deg tilt come back exactly."""
    truth = default_truth(tilt_deg=0.4)
    poses = plan_poses(truth, 20, targets=[(0,)])
    fit = fit_imu_to_camera(*_inputs(truth, poses))
    assert rotation_angle_deg(fit.imu_to_camera, truth.imu_to_camera) < 1e-6
    assert fit.tilt_estimated and abs(fit.board_tilt_deg - 0.4) < 1e-6
    assert np.allclose(fit.board_up, truth.board_up, atol=1e-8)
    assert fit.heading_spread_deg > 180 and not fit.warnings


def test_noise_gives_a_consistent_uncertainty():
    """With 0.02 deg gravity noise the error stays within a few sigma."""
    truth = default_truth(tilt_deg=0.4)
    poses = plan_poses(truth, 30, targets=[(0,)], seed=3)
    fit = fit_imu_to_camera(*_inputs(truth, poses, noise_deg=0.02, seed=4))
    error = rotation_angle_deg(fit.imu_to_camera, truth.imu_to_camera)
    assert error < 0.05
    assert 0.001 < np.max(fit.std_deg) < 0.05


def test_no_turn_about_the_vertical_warns_and_holds_the_board_level():
    """Without heading changes the tilt is not estimated and the warning says what to add."""
    truth = default_truth(tilt_deg=0.4)
    # the rig only pitches down by 35..65 deg, always facing the same way
    poses = [PoseTruth(rot_y(np.radians(el)), np.array([-0.4, 0.0, 0.4]))
             for el in np.linspace(35.0, 65.0, 10)]
    fit = fit_imu_to_camera(*_inputs(truth, poses))
    assert not fit.tilt_estimated and fit.board_tilt_deg == 0.0
    assert fit.heading_spread_deg < 1.0
    assert any('turned by 90-180 deg about the vertical' in w for w in fit.warnings)
    # the unseen tilt went into the mount
    assert 0.05 < rotation_angle_deg(fit.imu_to_camera, truth.imu_to_camera) < 0.45


def test_needs_two_poses():
    """One pose cannot give a rotation."""
    truth = default_truth()
    poses = plan_poses(truth, 1, targets=[(0,)])
    with pytest.raises(CalibrationError, match='at least 2 poses'):
        fit_imu_to_camera(*_inputs(truth, poses))


def test_heading_spread():
    """The arc holding every heading, across the wrap."""
    assert heading_spread_deg(np.radians([350.0, 10.0])) == pytest.approx(20.0)
    assert heading_spread_deg(np.radians([0.0, 90.0, 180.0, 270.0])) == pytest.approx(270.0)
