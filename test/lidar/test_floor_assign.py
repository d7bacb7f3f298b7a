"""Boresight without a prior in a box-shaped room: every fitting assignment, cues, refusal."""
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import calibrate_boresight
from accelcal_ros.lidar.floor_assign import AmbiguousFloorError
from accelcal_ros.lidar.wahba import rotation_angle_deg
import numpy as np
import pytest

TRUTH = sim.default_boresight()


def _positions(order, origin, tilts=None, seed=1):
    protocol = sim.simulate_protocol(TRUTH, tilts, room=sim.box_room(), seed=seed,
                                     scanner_origin=origin, order=order)
    return sim.positions_for_calibration(protocol)


@pytest.mark.parametrize('order, seed', [('xy', 0), ('yx', 1)])
def test_box_room_resolved_by_floor_height(order, seed):
    """
    Off-centre scanner in an 8 m cube: other turns fit as well, the floor height rules them out.

    Before the fix this room (scanner 3 m up) gave a rotation 180 deg from the truth; a first
    version of the height cue let a quarter turn through (walls 3.7-4.3 m away, seed 0).
    """
    positions = _positions(order, (0.3, 0.2, 3.0), seed=seed)
    res = calibrate_boresight(positions, None)
    assert rotation_angle_deg(res.rotation, TRUTH) < 0.05
    assert any('ruled out' in w and 'below the scanner' in w for w in res.warnings)
    with_prior = calibrate_boresight(positions, sim.nominal_mount())
    assert rotation_angle_deg(with_prior.rotation, TRUTH) < 0.3


@pytest.mark.parametrize('order', ['xy', 'yx'])
def test_box_room_centred_is_refused_with_candidates(order):
    """Scanner at the centre of the cube: nothing tells the half turns apart -> refuse."""
    # the upright scanner at the centre never sees the floor (its lowest beam hits a wall)
    tilts = [t for t in sim.paper_protocol_tilts_deg() if t != (0.0, 0.0)]
    positions = _positions(order, (0.0, 0.0, 4.0), tilts)
    with pytest.raises(AmbiguousFloorError, match='--prior-rpy-deg') as err:
        calibrate_boresight(positions, None)
    cands = err.value.candidates
    assert len(cands) >= 2
    assert min(rotation_angle_deg(c.rotation, TRUTH) for c in cands) < 0.1
    assert any(rotation_angle_deg(c.rotation, TRUTH) > 170 for c in cands)
    assert 'rpy [' in str(err.value)
    res = calibrate_boresight(positions, sim.nominal_mount())
    assert rotation_angle_deg(res.rotation, TRUTH) < 0.05


def test_default_room_no_prior_unchanged():
    """The furnished 10 x 8 x 3 m room still resolves without a prior (order y then x)."""
    protocol = sim.simulate_protocol(TRUTH, seed=3, order='yx')
    res = calibrate_boresight(sim.positions_for_calibration(protocol), None)
    assert rotation_angle_deg(res.rotation, TRUTH) < 0.05
    assert np.all(np.isfinite(res.rpy_std_deg))


def test_cli_refuses_ambiguous_room_and_prior_decides(tmp_path, capsys):
    """``accelcal boresight`` exits 1 with one line listing candidates; the prior decides."""
    from accelcal_ros.cli import main
    from accelcal_ros.lidar.boresight import load_boresight

    tilts = [t for t in sim.paper_protocol_tilts_deg() if t != (0.0, 0.0)]
    protocol = sim.simulate_protocol(TRUTH, tilts, room=sim.box_room(), seed=4,
                                     scanner_origin=(0.0, 0.0, 4.0), order='yx')
    sim.write_protocol(tmp_path / 'box', protocol, 'binary')
    out = tmp_path / 'bs.yaml'
    assert main(['boresight', str(tmp_path / 'box'), '-o', str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and 'rpy [' in err and '--prior-rpy-deg' in err
    assert not out.exists()
    assert main(['boresight', str(tmp_path / 'box'), '-o', str(out),
                 '--prior-rpy-deg', '0', '45', '0']) == 0
    assert rotation_angle_deg(load_boresight(out), TRUTH) < 0.05


def _box_planes(origin, size=(8.0, 8.0, 8.0), counts=None, order='xy', seed=0):
    """Exact plane sets of an empty box seen from ``origin`` at paper B's tilts."""
    from accelcal_ros.lidar.floor_assign import PlaneSet

    rng = np.random.default_rng(seed)
    o = np.asarray(origin, float)
    inward = np.array([[0, 0, 1], [0, 0, -1], [1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0.0]])
    dist = np.array([o[2], size[2] - o[2], o[0], size[0] - o[0], o[1], size[1] - o[1]])
    counts = np.ones(6) * 5000 if counts is None else np.asarray(counts, float)
    sets, gravity = [], []
    for a, b in sim.paper_protocol_tilts_deg():
        c = sim.tilt_rotation(a, b, order)
        sets.append(PlaneSet(inward @ c, dist.copy(), counts.copy()))   # rows: C^T e
        gravity.append(TRUTH @ c.T @ [0, 0, 1.0] + rng.normal(0, 2e-4, 3))
    return sets, np.array(gravity)


@pytest.mark.parametrize('order', ['xy', 'yx'])
def test_select_floor_cues_on_exact_box_planes(order):
    """
    Exact box planes: the cues, one by one.

    Centred cube: refuse. A smaller ceiling rules out the half turns (which call the ceiling
    the floor somewhere) but not the quarter turns that only swap floor and walls: still
    refused. An off-centre scanner: the floor height decides.
    """
    from accelcal_ros.lidar.floor_assign import select_floor

    sets, gravity = _box_planes((4.0, 4.0, 4.0), order=order)
    with pytest.raises(AmbiguousFloorError) as err:
        select_floor(sets, gravity)
    equal = err.value.candidates
    assert any(rotation_angle_deg(c.rotation, TRUTH) < 0.1 for c in equal)
    assert any(rotation_angle_deg(c.rotation, TRUTH) > 170 for c in equal)
    sets, gravity = _box_planes((4.0, 4.0, 4.0), counts=[6000, 2000, 4000, 4000, 4000, 4000],
                                order=order)
    with pytest.raises(AmbiguousFloorError) as err:
        select_floor(sets, gravity)
    left = err.value.candidates
    assert len(left) < len(equal)
    assert any(rotation_angle_deg(c.rotation, TRUTH) < 0.1 for c in left)
    assert all(rotation_angle_deg(c.rotation, TRUTH) < 170 for c in left)
    # scanner 1.2 m above the floor of the equal box: the floor height decides
    sets, gravity = _box_planes((3.0, 4.5, 1.2), order=order)
    r, choice, notes = select_floor(sets, gravity)
    assert rotation_angle_deg(r, TRUTH) < 0.1 and np.all(choice == 0)
    assert 'below the scanner' in notes[0]
