"""
LiDAR journeys: paper B's 15-position protocol (bag and files) and one moving-platform scan.

One scanner everywhere: boresight :data:`BORESIGHT_TRUTH` (the simulator's default VLP-16
mount, tilted 45 deg) and lever arm :data:`LEVER_ARM_M` (the README's ``--lever-arm 0.1 0
0.2``), so the boresight ``accelcal boresight`` finds is the one the drive was made with.
"""
import os
from pathlib import Path

from accelcal_ros.lidar import scanner_sim
from accelcal_ros.lidar.cloud import make_cloud, xyz
from accelcal_ros.lidar.pcd import write_pcd
from accelcal_ros.lidar.poses import write_poses_csv
from accelcal_ros.recording.sim_bags import write_protocol_bag
import numpy as np

BORESIGHT_TRUTH = scanner_sim.default_boresight()
LEVER_ARM_M = (0.1, 0.0, 0.2)
STILL_S = 3.0
SCAN_START_S = 1_700_000_100.0
"""Absolute time (s) of the scan written as ``scan.pcd`` (its points carry ``timestamp``)."""


def write(directory: str) -> None:
    """Write ``rosbag2_boresight``, ``boresight_positions/``, ``scan.pcd`` and ``poses.csv``."""
    positions = scanner_sim.simulate_protocol(BORESIGHT_TRUTH, seed=5, still_s=STILL_S)
    write_protocol_bag(Path(directory) / 'rosbag2_boresight', 'mcap', positions)
    scanner_sim.write_protocol(os.path.join(directory, 'boresight_positions'), positions,
                               'binary')
    moving = scanner_sim.simulate_moving_platform(
        duration_s=0.2, seed=2, boresight=BORESIGHT_TRUTH, lever_arm_m=LEVER_ARM_M,
        scan_start_s=SCAN_START_S)
    cloud = moving.cloud
    absolute = make_cloud(xyz(cloud), cloud['intensity'], cloud['ring'],
                          SCAN_START_S + cloud['time'].astype(np.float64), 'timestamp')
    write_pcd(os.path.join(directory, 'scan.pcd'), absolute, 'binary')
    write_poses_csv(os.path.join(directory, 'poses.csv'), moving.poses)
