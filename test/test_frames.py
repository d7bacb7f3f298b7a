"""Frame and sign conventions: REP-103/145 and the mapping of paper A's convention."""
import math

from accelcal_ros.errors import InputError
from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, down_in_camera,
                                 paper_gravity_from_specific_force, paper_roll_pitch,
                                 rep103_from_paper_roll_pitch,
                                 roll_pitch_from_specific_force, rotation_from_rpy_radians,
                                 rotation_matrix_from_list, rpy_radians_from_rotation,
                                 specific_force_from_roll_pitch)
from hypothesis import given, settings
from hypothesis import strategies as st
import numpy as np
import pytest

angles = st.floats(-np.pi + 1e-6, np.pi - 1e-6)
pitches = st.floats(-np.pi / 2 + 1e-6, np.pi / 2 - 1e-6)


@settings(max_examples=200, deadline=None)
@given(angles, pitches, angles)
def test_rpy_round_trip_and_specific_force(roll, pitch, yaw):
    """R = Rz Ry Rx; f = R^T [0, 0, 1] at rest; roll/pitch come back from f."""
    rotation = rotation_from_rpy_radians(roll, pitch, yaw)
    assert np.allclose(rpy_radians_from_rotation(rotation), (roll, pitch, yaw), atol=1e-7) \
        or abs(abs(pitch) - np.pi / 2) < 1e-4
    f = specific_force_from_roll_pitch(roll, pitch)
    assert np.allclose(f, rotation.T @ [0.0, 0.0, 1.0])
    r, p = roll_pitch_from_specific_force(3.7 * f)  # any unit
    assert p == pytest.approx(pitch, abs=1e-9)
    assert r == pytest.approx(roll, abs=1e-9) or abs(abs(pitch) - np.pi / 2) < 1e-6


@settings(max_examples=200, deadline=None)
@given(st.floats(-np.pi + 1e-3, np.pi - 1e-3), pitches)
def test_paper_equations_on_specific_force_map_to_rep103(roll, pitch):
    """Paper A eqs. (2)-(3) fed with f give (-roll, pitch) of REP-103; the map undoes it."""
    f = specific_force_from_roll_pitch(roll, pitch)
    r_paper, p_paper = paper_roll_pitch(f)
    r_rep, p_rep = roll_pitch_from_specific_force(f)
    assert r_paper == pytest.approx(-r_rep, abs=1e-9)
    assert p_paper == pytest.approx(p_rep, abs=1e-9)
    assert rep103_from_paper_roll_pitch(r_paper, p_paper) == pytest.approx((r_rep, p_rep))


def test_paper_worked_example_is_inconsistent_in_roll_only():
    """The paper's level reading [0, 0, -1] gives roll 180 deg by eq. (2); pitch is fine."""
    g_level = paper_gravity_from_specific_force([0.0, 0.0, 1.0])
    assert np.allclose(g_level, [0.0, 0.0, -1.0])
    roll, pitch = paper_roll_pitch(g_level)
    assert abs(roll) == pytest.approx(np.pi) and pitch == pytest.approx(0.0)
    # its K=100 example: |pitch| = 3.31 deg whichever sign convention is used
    g = np.array([-0.062, -0.0076, -1.071])
    assert abs(np.degrees(paper_roll_pitch(g)[1])) == pytest.approx(3.31, abs=0.01)
    assert abs(np.degrees(roll_pitch_from_specific_force(-g)[1])) == \
        pytest.approx(3.31, abs=0.01)


def test_level_and_tilted_examples():
    """Level reads +1 g on z; nose-up pitch reads -x; right-side-down roll reads +y."""
    assert specific_force_from_roll_pitch(0.0, 0.0) == pytest.approx([0, 0, 1])
    assert specific_force_from_roll_pitch(0.0, np.radians(30))[0] == pytest.approx(-0.5)
    assert specific_force_from_roll_pitch(np.radians(30), 0.0)[1] == pytest.approx(0.5)


def test_no_nan_at_pitch_90():
    """Pitch +-90 deg: pitch is exact and roll is finite (undefined, reported as 0)."""
    r, p = roll_pitch_from_specific_force(np.array([[-1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))
    assert np.all(np.isfinite(r)) and p == pytest.approx([np.pi / 2, -np.pi / 2])


def test_camera_down_vector_and_rotation_validation():
    """Camera along body +x: level gravity points along optical +y (down in the image)."""
    assert down_in_camera(0.0, 0.0) == pytest.approx([0.0, 1.0, 0.0])
    # REP-103: positive pitch is nose down, so gravity gets a forward (+z optical) part
    assert down_in_camera(0.0, np.radians(30))[2] == pytest.approx(0.5)
    assert np.allclose(rotation_matrix_from_list(DEFAULT_IMU_TO_CAMERA.ravel()),
                       DEFAULT_IMU_TO_CAMERA)
    with pytest.raises(InputError, match='9 row-major'):
        rotation_matrix_from_list([1, 0, 0])
    with pytest.raises(InputError, match='not a rotation'):
        rotation_matrix_from_list(np.diag([1.0, 1.0, -1.0]).ravel(), 'imu_to_camera')
    with pytest.raises(InputError, match='NaN'):
        rotation_matrix_from_list([np.nan] * 9)


@pytest.mark.parametrize('roll, pitch, ok', [
    (0.0, 0.0, True), (math.pi, math.pi / 2, True), (-math.pi, -math.pi / 2, True),
    (0.0, 4.0, False), (1e300, 0.0, False), (0.0, math.nan, False), (math.inf, 0.0, False),
    (3.2, 0.0, False), (0.0, -1.6, False), ('x', 0.0, False),
])
def test_attitude_range_is_checked_where_an_attitude_enters(roll, pitch, ok):
    """Roll +-pi, pitch +-pi/2, finite (issue 26): one shared check with the reason."""
    from accelcal_ros.errors import InputError
    from accelcal_ros.frames import attitude_problem, check_attitude

    assert (attitude_problem(roll, pitch) is None) == ok
    if ok:
        assert check_attitude(roll, pitch) == (float(roll), float(pitch))
    else:
        with pytest.raises(InputError, match='^attitude at 1 s: '):
            check_attitude(roll, pitch, 'attitude at 1 s')


def test_out_of_range_attitudes_are_refused_by_the_p2p_pipeline_and_the_stitcher():
    """p2p's pipeline raises (the node counts it); the stitcher's policy counts and says it."""
    from accelcal_ros.errors import InputError
    from accelcal_ros.p2p.pipeline import P2PPipeline
    from accelcal_ros.p2p.params import P2P_PARAMS
    from accelcal_ros.panorama.frame_sets import FrameSetPolicy
    from accelcal_ros.panorama.params import STITCHER_PARAMS

    pipeline = P2PPipeline({s.name: s.default for s in P2P_PARAMS})
    with pytest.raises(InputError, match='outside roll'):
        pipeline.add_attitude(1.0, 0.0, 4.0)
    assert pipeline.add_attitude(1.0, 0.1, 0.2) == []
    logged = []
    policy = FrameSetPolicy(['cam0'], {s.name: s.default for s in STITCHER_PARAMS},
                            log=lambda level, text: logged.append(text))
    assert not policy.add_attitude(1.0, 1e300, 0.0, 0.0)
    assert not policy.add_attitude(2.0, 0.0, math.nan, 0.0)
    assert policy.add_attitude(3.0, 0.1, 0.2, 0.0)
    assert policy.rejected_attitudes == 2
    assert len(logged) == 1 and 'outside roll +-pi' in logged[0]
