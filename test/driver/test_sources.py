"""The simulated source's poll schedule: on the sample grid, batched at high rates."""
from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.driver.sources import SimSource
import numpy as np
import pytest


def test_late_wakeups_do_not_delay_later_polls():
    """A poll 3 ms late at 100 Hz returns the due sample; the next poll stays on the grid."""
    now = [1000.0]
    source = SimSource(SimulatedAdxl345(rate_hz=100.0), clock=lambda: now[0])
    source.start()
    stamps = []
    for _ in range(50):
        now[0] = source.next_poll_time() + 0.003  # every wake-up 3 ms late
        stamps.extend(source.poll().stamps)
    assert len(stamps) == 50
    assert np.allclose(np.diff(stamps), 0.01)
    assert source.next_poll_time() == pytest.approx(1000.0 + 50 * 0.01)


def test_high_rates_are_batched_without_loss():
    """At 3200 Hz each poll carries four samples; every sample is returned exactly once."""
    now = [0.0]
    source = SimSource(SimulatedAdxl345(rate_hz=3200.0), clock=lambda: now[0])
    source.start()
    sizes, stamps = [], []
    for _ in range(100):
        now[0] = source.next_poll_time()
        batch = source.poll()
        sizes.append(len(batch))
        stamps.extend(batch.stamps)
    assert sizes[0] == 4 and set(sizes[1:]) == {4}
    assert np.allclose(np.diff(stamps), 1 / 3200.0) and len(stamps) == 400
