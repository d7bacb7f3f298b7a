"""
The simulated sensor's truth against what a graph published (demo and graph tests).

The ``sim`` backend of ``imu_driver`` publishes ``sim/attitude_truth``
(geometry_msgs/Vector3Stamped: x = roll, y = pitch in rad, the same stamps as
``imu/data_raw``). :func:`dwell_errors_deg` compares an attitude stream with it over the
simulator's still dwells. Messages are read by attribute only (no ROS import).
"""
from typing import Any, Dict, Sequence, Tuple

from accelcal_ros.rosutil.stamps import stamp_to_seconds
import numpy as np


def dwell_errors_deg(attitude_msgs: Sequence[Any], truth_msgs: Sequence[Any], margin: int = 20,
                     max_pitch_deg: float = 80.0) -> Dict[Tuple[float, float], np.ndarray]:
    """
    Return ``{(roll, pitch): [mean roll error, mean pitch error] (deg)}`` per still dwell.

    Messages are matched by stamp; a sample is in a still dwell when the truth is the same
    ``margin`` samples before and after it. Orientations beyond ``max_pitch_deg`` are
    skipped (roll is undefined at pitch +-90 deg).
    """
    truth = sorted((stamp_to_seconds(m.header.stamp), m.vector.x, m.vector.y)
                   for m in truth_msgs)
    by_stamp = {round(t, 6): k for k, (t, _, _) in enumerate(truth)}
    dwells: Dict[Tuple[float, float], list] = {}
    for msg in attitude_msgs:
        k = by_stamp.get(round(stamp_to_seconds(msg.header.stamp), 6))
        if k is None or k < margin or k + margin >= len(truth):
            continue
        _, roll, pitch = truth[k]
        if any(abs(truth[j][1] - roll) > 1e-9 or abs(truth[j][2] - pitch) > 1e-9
               for j in (k - margin, k + margin)) or abs(pitch) > np.radians(max_pitch_deg):
            continue
        err_roll = np.angle(np.exp(1j * (msg.vector.x - roll)))
        dwells.setdefault((round(float(np.degrees(roll)), 1), round(float(np.degrees(pitch)), 1)),
                          []).append((err_roll, msg.vector.y - pitch))
    return {key: np.degrees(np.mean(v, axis=0)) for key, v in dwells.items() if len(v) >= 20}
