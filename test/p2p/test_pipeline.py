"""The p2p node's logic without ROS: attitude matching, bad input, ambiguity, parameters."""
from accelcal_ros.camera import CameraModel
from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rpy_radians_from_rotation
from accelcal_ros.p2p import render, solver
from accelcal_ros.p2p.params import emitters_reason, P2P_PARAMS, rotation_reason
from accelcal_ros.p2p.pipeline import P2PPipeline
from accelcal_ros.paramspec import check_all
import numpy as np
import pytest

EMITTERS = [-0.5, 0.0, 0.0, 0.5, 0.0, 0.0]
CAMERA = CameraModel.from_fov(640, 480, 60.0)


def defaults(**changes):
    values = {spec.name: spec.default for spec in P2P_PARAMS}
    values.update({'emitters': EMITTERS, 'threshold': 60})
    values.update(changes)
    return values


def frame(yaw_deg=90.0, roll_deg=3.0, pitch_deg=15.0, position=(0.2, -4.0, 1.2)):
    rotation, translation = render.pose_from_camera_attitude(
        *np.radians([roll_deg, pitch_deg, yaw_deg]), position)
    image, _, _ = render.render_emitters(np.reshape(EMITTERS, (2, 3)), rotation, translation,
                                         CAMERA, noise_std=1.0)
    roll, pitch, _ = rpy_radians_from_rotation(rotation.T @ DEFAULT_IMU_TO_CAMERA)
    return image, rotation, translation, roll, pitch


def ready_pipeline(**changes):
    pipe = P2PPipeline(defaults(**changes))
    assert pipe.set_camera_info(CAMERA.camera_matrix.reshape(-1), [0.0] * 5, 'plumb_bob',
                                640, 480) is None
    return pipe


def test_pose_from_image_and_matched_attitude():
    pipe = ready_pipeline()
    image, rotation, translation, roll, pitch = frame()
    for k in range(5):
        pipe.add_attitude(10.0 + 0.01 * k, roll, pitch)
    [result] = pipe.add_image(10.02, 'cam_optical', image)
    assert result.solution is not None, result.reason
    assert result.frame_id == 'cam_optical' and result.stamp_s == 10.02
    assert np.linalg.norm(result.solution.translation - translation) < 0.01
    assert abs(result.solution.yaw - solver.yaw_from_rotation(rotation)) < 1e-3


def test_image_waits_for_its_attitude():
    pipe = ready_pipeline()
    image, rotation, translation, roll, pitch = frame()
    pipe.add_attitude(9.90, roll, pitch)
    assert pipe.add_image(10.0, 'cam', image) == []          # attitude stream is behind
    assert pipe.add_attitude(9.95, roll, pitch) == []
    [result] = pipe.add_attitude(10.001, roll, pitch)
    assert result.solution is not None and result.stamp_s == 10.0


def test_image_without_close_attitude_gets_a_reason():
    pipe = ready_pipeline(attitude_tolerance_s=0.02)
    image, *_, roll, pitch = frame()
    pipe.add_attitude(9.5, roll, pitch)
    assert pipe.add_image(10.0, 'cam', image) == []
    [result] = pipe.add_attitude(10.5, roll, pitch)          # jumped past the image
    assert result.solution is None and 'no attitude within 0.02 s' in result.reason
    [result] = ready_pipeline().add_image(10.0, 'cam', image)
    assert 'no attitude received yet' in result.reason


def test_missing_camera_info_and_bad_camera_info():
    image, *_, roll, pitch = frame()
    pipe = P2PPipeline(defaults())
    pipe.add_attitude(10.0, roll, pitch)
    [result] = pipe.add_image(10.0, 'cam', image)
    assert result.solution is None and 'no camera_info' in result.reason
    reason = pipe.set_camera_info([0.0] * 9, [], '', 640, 480)
    assert 'not calibrated' in reason
    [result] = pipe.add_image(10.0, 'cam', image)
    assert 'not calibrated' in result.reason
    assert 'not supported' in pipe.set_camera_info(CAMERA.camera_matrix.reshape(-1),
                                                   [0.1, 0, 0, 0], 'weird', 640, 480)
    pipe.set_camera_info(CAMERA.camera_matrix.reshape(-1), [], '', 1280, 960)
    [result] = pipe.add_image(10.0, 'cam', image)
    assert 'does not match camera_info 1280x960' in result.reason


def test_nan_attitude_and_no_emitters():
    pipe = ready_pipeline()
    image, *_, roll, pitch = frame()
    with pytest.raises(InputError, match='not finite'):  # refused where it enters
        pipe.add_attitude(10.0, float('nan'), pitch)
    with pytest.raises(InputError, match='outside roll'):
        pipe.add_attitude(10.0, roll, 4.0)
    [result] = pipe.add_image(10.0, 'cam', image)  # nothing was stored
    assert result.solution is None and 'no attitude received yet' in result.reason
    pipe.add_attitude(11.0, roll, pitch)
    [result] = pipe.add_image(11.0, 'cam', np.zeros((480, 640), np.uint8))
    assert 'no pixel above threshold' in result.reason


def test_swapped_emitter_order_gives_the_turned_pose():
    pipe = ready_pipeline(order='right_to_left')
    image, rotation, translation, roll, pitch = frame()
    pipe.add_attitude(10.0, roll, pitch)
    [result] = pipe.add_image(10.0, 'cam', image)
    assert result.solution is not None  # swapped emitters: a pose, turned 180 deg about z
    centre = -rotation.T @ translation
    assert np.allclose(result.solution.camera_position, centre * [-1, -1, 1], atol=0.02)
    assert abs(abs(result.solution.yaw - solver.yaw_from_rotation(rotation)) - np.pi) < 1e-3


def test_ambiguity_resolved_by_continuity_or_reported():
    # Emitters at different heights seen from between them: two valid poses.
    emitters = [0.0, 0.0, 0.0, 1.0, 0.0, 1.0]
    rng = np.random.default_rng(3)
    for _ in range(2000):
        position = rng.uniform([-4, -6, -2], [4, -2, 3])
        yaw = np.degrees(np.arctan2(-position[1], 0.5 - position[0])) + rng.uniform(-5, 5)
        rotation, translation = render.pose_from_camera_attitude(
            *np.radians([rng.uniform(-10, 10), rng.uniform(-20, 20), yaw]), position)
        points = np.reshape(emitters, (2, 3))
        cam = points @ rotation.T + translation
        if np.any(cam[:, 2] < 1.0):
            continue
        down = rotation @ [0, 0, -1.0]
        if len(solver.solve(cam, points, down)) == 2:
            break
    else:
        pytest.fail('no two-solution configuration found')
    image, uv, _ = render.render_emitters(points, rotation, translation, CAMERA, noise_std=0)
    roll, pitch, _ = rpy_radians_from_rotation(rotation.T @ DEFAULT_IMU_TO_CAMERA)
    pipe = ready_pipeline(emitters=emitters, order='left_to_right')
    # Pin the order to the rendered one (whatever left/right says) by choosing it here.
    pipe.configure({'order': 'left_to_right' if uv[0, 0] < uv[1, 0] else 'right_to_left'})
    pipe.add_attitude(10.0, roll, pitch)
    [result] = pipe.add_image(10.0, 'cam', image)
    assert result.solution is None and 'ambiguous' in result.reason
    assert len(result.candidates) == 2
    true_index = int(np.argmin([np.linalg.norm(c.translation - translation)
                                for c in result.candidates]))
    pipe.last_pose = (9.9, result.candidates[true_index])
    pipe.add_attitude(10.1, roll, pitch)
    [result] = pipe.add_image(10.1, 'cam', image)
    assert result.resolved_by_continuity
    assert np.linalg.norm(result.solution.translation - translation) < 0.02


def test_parameter_validation():
    _, reasons = check_all(P2P_PARAMS, {'emitters': [0, 0, 0, 0, 0, 1.0]})
    assert reasons and 'vertical line' in reasons[0]
    assert 'coincide' in emitters_reason([1.0, 2, 3, 1, 2, 3])
    assert 'expected 6' in emitters_reason([1.0, 2, 3])
    assert emitters_reason(EMITTERS) is None
    assert 'within +-1,000,000 m' in emitters_reason([0, 0, 0, 1e300, 0, 0])
    assert 'within' in emitters_reason([0, 0, 0, 0, 0, -1.5e6])
    assert 'not a rotation' in rotation_reason([1.0] * 9)
    assert rotation_reason(list(DEFAULT_IMU_TO_CAMERA.reshape(-1))) is None
    _, reasons = check_all(P2P_PARAMS, {'order': 'diagonal', 'threshold': 300})
    assert len(reasons) == 2
    with pytest.raises(InputError, match='area'):
        P2PPipeline(defaults(min_area_px=100, max_area_px=10))


def test_an_emitter_past_the_lens_fold_gets_a_reason_not_a_pose():
    """
    A blob where the lens model has no ray is refused with the reason: no pose.

    k1 = -0.6 at f = 400 px has no ray past 199 px from the centre (here the corner).
    """
    pipe = P2PPipeline(defaults())
    assert pipe.set_camera_info([400.0, 0, 320, 0, 400.0, 240, 0, 0, 1],
                                [-0.6, 0.0, 0.0, 0.0, 0.0], 'plumb_bob', 640, 480) is None
    image = render.draw_spots((480, 640), [[330.0, 250.0], [600.0, 450.0]], 1.5, 240)
    pipe.add_attitude(5.0, 0.0, 0.0)
    [result] = pipe.add_image(5.0, 'cam', image.astype(np.uint8))
    assert result.solution is None and result.candidates == []
    assert "(600, 450) is outside the lens model's valid range" in result.reason
    assert result.detection is not None and not result.detection.ok
