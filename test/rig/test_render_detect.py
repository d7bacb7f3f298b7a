"""Ground-truth renderer and chessboard detection: corners, ordering, gravity."""
from accelcal_ros.errors import InputError
from accelcal_ros.rig.board import Board, parse_board_size
from accelcal_ros.rig.detect import detect_board, guess_board_size
from accelcal_ros.rig.render import (board_in_camera, default_truth, imu_samples, plan_poses,
                                     PoseTruth, Renderer)
import cv2
import numpy as np
import pytest


@pytest.fixture(scope='module')
def scene():
    """Return a rendered ring, a few poses (single and shared views) and a renderer."""
    truth = default_truth()
    return truth, plan_poses(truth, 5), Renderer(truth)


def _true_corners(truth, pose, index):
    r_cb, t_cb = board_in_camera(truth, pose, index)
    px, _ = cv2.projectPoints(truth.board.object_points(), cv2.Rodrigues(r_cb)[0], t_cb,
                              truth.K[index], truth.D[index])
    return px.reshape(-1, 2)


def test_board_needs_one_even_and_one_odd_count():
    """A board that looks the same after a half turn is refused; sizes parse."""
    with pytest.raises(InputError, match='one count of inner corners must be even'):
        Board(8, 6, 0.03)
    with pytest.raises(InputError, match='COLSxROWS'):
        parse_board_size('9 by 6')
    assert parse_board_size(' 11x8 ') == (11, 8)
    # OpenCV's detector segfaults once cols * rows passes 2**31: refused before it
    for text in ('46341x46342', '3x2147483648', '101x100'):
        with pytest.raises(InputError, match='at most 100 inner corners'):
            parse_board_size(text)
    with pytest.raises(InputError, match='at most 100 inner corners'):
        Board(101, 100, 0.03)
    with pytest.raises(InputError, match='at least 0.001 m'):
        Board(9, 6, 1e-9)


def test_detected_corners_match_the_projection_in_every_camera(scene):
    """Every camera of a pose names each corner alike (board-frame order), sub-pixel exact."""
    truth, poses, renderer = scene
    errors = []
    for pose in poses:
        for i in range(3):
            found = detect_board(renderer.render(pose, i), truth.board)
            assert (found is not None) == (i in pose.visible)
            if found is not None:
                errors.append(np.linalg.norm(found.corners - _true_corners(truth, pose, i),
                                             axis=1))
    errors = np.concatenate(errors)
    assert len(errors) >= 7 * truth.board.count
    assert np.sqrt(np.mean(errors ** 2)) < 0.1 and errors.max() < 0.4


def test_half_turned_image_gives_the_same_physical_corners(scene):
    """The half-turn test: an image turned by 180 deg still starts at the same corner."""
    truth, poses, renderer = scene
    image = renderer.render(poses[0], poses[0].visible[0])
    h, w = image.shape
    direct = detect_board(image, truth.board)
    turned = detect_board(cv2.rotate(image, cv2.ROTATE_180), truth.board)
    back = np.column_stack([w - 1 - turned.corners[:, 0], h - 1 - turned.corners[:, 1]])
    assert np.abs(back - direct.corners).max() < 0.05


def test_other_board_size_is_recognised(scene):
    """A failed detection can say which board the image shows."""
    truth, poses, renderer = scene
    image = renderer.render(poses[0], poses[0].visible[0])
    assert detect_board(image, Board(9, 6, 0.025)) is None
    assert guess_board_size(image, Board(9, 6, 0.025)) == [(11, 8)]


def test_specific_force_is_up_in_the_imu_frame():
    """REP-145: a level still rig reads +g on its z axis."""
    truth = default_truth()
    level = PoseTruth(np.eye(3), np.zeros(3))
    samples = imu_samples(truth, level, np.random.default_rng(0), noise_m_s2=0.0)
    assert np.allclose(samples['a'], [0.0, 0.0, 9.80665])
