"""IMU journey: a calibration session of the simulated ADXL345 as a bag and as CSV."""
import os
from pathlib import Path

from accelcal_ros.driver.sim_sensor import SimulatedAdxl345
from accelcal_ros.recording.sim_bags import write_imu_bag
from accelcal_ros.sensor.model import paper_a_model
from accelcal_ros.sensor.recording import save_recording
from accelcal_ros.sensor.units import g_to_mps2, STANDARD_GRAVITY_M_S2
import numpy as np

SENSOR = paper_a_model(500)
"""The one simulated accelerometer of every sample recording (paper A, Table 1): all IMU
data is raw, so ``--calibration calib.yaml`` (fitted on ``rosbag2_imu``) applies to all."""


def raw_m_s2(force_m_s2: np.ndarray) -> np.ndarray:
    """Return what :data:`SENSOR` reads (m/s^2) for the true specific force (m/s^2)."""
    return g_to_mps2(SENSOR.distort(np.asarray(force_m_s2) / STANDARD_GRAVITY_M_S2))


RATE_HZ = 100.0
DURATION_S = 96.0
"""24 still dwells of 3 s with 1 s turns between them (the simulator's default poses)."""


def session(seed: int) -> 'tuple[np.ndarray, np.ndarray]':
    """Return the times (s) and raw readings (m/s^2) of one simulated calibration session."""
    sensor = SimulatedAdxl345(truth=SENSOR, rate_hz=RATE_HZ, seed=seed)
    t = np.arange(int(round(DURATION_S * RATE_HZ))) / RATE_HZ
    return t, g_to_mps2(sensor.read(t))


def write(directory: str) -> None:
    """Write ``rosbag2_imu`` (mcap, ``/imu/data_raw``) and ``rec.csv``."""
    t, accel = session(seed=1)
    write_imu_bag(Path(directory) / 'rosbag2_imu', 'mcap', t, accel)
    t, accel = session(seed=2)
    save_recording(os.path.join(directory, 'rec.csv'), t, accel)
