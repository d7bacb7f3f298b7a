"""Still-dwell detection on the simulated sensor's dwell/move schedule."""
from accelcal_ros.calibration.static_detector import StaticDetector
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
import numpy as np
import pytest


def _recording(rate_hz=100.0, dwell_s=2.0, move_s=1.0, poses=6, seed=0):
    sim = SimulatedAdxl345(poses_deg=[(0, 0), (90, 0), (0, 60), (180, 0), (-90, 30),
                                      (0, -60)][:poses],
                           rate_hz=rate_hz, dwell_s=dwell_s, move_s=move_s, seed=seed)
    t = np.arange(0.0, sim.period_s * poses, 1.0 / rate_hz)
    return sim, t, sim.read(t)


@pytest.mark.parametrize('rate_hz', [100.0, 800.0])
def test_every_dwell_found_with_its_true_mean(rate_hz):
    sim, t, a = _recording(rate_hz)
    det = StaticDetector()
    det.add_many(t, a)
    det.flush()
    segments = [s.final for s in det.ended if s.final is not None
                and s.final.duration_s >= 1.0]
    assert len(segments) == 6
    for k, seg in enumerate(segments):
        # Each segment lies inside dwell k (start within the dwell, at most 0.15 s of
        # the slow start of the next move included).
        assert k * sim.period_s - 0.15 <= seg.t_start < k * sim.period_s + 0.5
        assert seg.t_end <= k * sim.period_s + sim.dwell_s + 0.15
        truth = sim.truth.distort(sim.true_specific_force([k * sim.period_s + 0.5]))[0]
        assert np.all(np.abs(seg.mean_g - truth) < 5 * seg.std_of_mean_g + 4e-4)


def test_motion_is_not_still():
    sim, t, a = _recording()
    det = StaticDetector()
    still_while_moving = 0
    for ti, ai in zip(t, a):
        det.add(ti, ai)
        mid_move = (ti % sim.period_s) - sim.dwell_s
        if 0.2 < mid_move < 0.8 and det.still:
            still_while_moving += 1
    assert still_while_moving == 0


def test_nan_skipped_saturated_rejected_and_breaks_the_dwell():
    sim, t, a = _recording(poses=2)
    a = a.copy()
    a[50] = np.nan
    a[120, 2] = 16.0
    det = StaticDetector()
    used = det.add_many(t, a)
    assert used == len(t) - 2
    assert det.rejected_nan == 1 and det.rejected_saturated == 1
    assert det.ended and det.ended[0].blocks[-1].t_end < t[120]
    det.flush()
    for seg in det.ended:
        if seg.final is not None:
            assert np.all(np.isfinite(seg.final.mean_g))
            assert seg.final.mean_g[2] < 1.5


def test_time_going_backwards_breaks_the_dwell():
    det = StaticDetector()
    t = np.arange(0.0, 2.0, 0.01)
    a = np.tile([0.0, 0.0, 1.0], (len(t), 1))
    det.add_many(t, a)
    assert det.still
    det.add(0.5, [0.0, 0.0, 1.0])
    assert not det.still
    assert det.ended


def test_bad_settings_rejected():
    with pytest.raises(ValueError):
        StaticDetector(window_s=0.0)
