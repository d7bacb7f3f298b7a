"""
``accelcal study rig``: rig calibration accuracy against the number of poses.

A rendered 3-camera ring (:func:`.render.default_truth`, 0.4 deg board tilt) is
calibrated from its first N poses (the pose plan cycles through single cameras and
neighbouring pairs); the errors against the known values are printed per N.
"""
import os
import tempfile
from typing import List, Sequence

from accelcal_ros.recording.progress import track
from accelcal_ros.rig.calibrate import calibrate_directory, RigCalibration
from accelcal_ros.rig.extrinsics import rotation_angle_deg
from accelcal_ros.rig.render import (default_truth, plan_poses, Renderer, RigTruth,
                                     write_dataset)
import numpy as np


def errors(result: RigCalibration, truth: RigTruth) -> dict:
    """Errors of a calibration against the truth: focal %, principal point px, angles deg."""
    focal = [100 * abs(result.K[i][j, j] / truth.K[i][j, j] - 1) for i in range(3)
             for j in range(2)]
    centre = [float(np.linalg.norm(result.K[i][:2, 2] - truth.K[i][:2, 2])) for i in range(3)]
    rig = [rotation_angle_deg(result.fit.rotations[i], truth.R[i]) for i in range(3)]
    return {'focal_pct': max(focal), 'centre_px': max(centre), 'R_0i_deg': max(rig),
            'imu_to_camera_deg': rotation_angle_deg(result.mount.imu_to_camera,
                                                    truth.imu_to_camera),
            'tilt_error_deg': abs(result.mount.board_tilt_deg - truth.board_tilt_deg)}


def run_study(pose_counts: Sequence[int], seed: int = 1) -> List[str]:
    """Calibrate from the first N poses for each N; return the printed lines."""
    truth = default_truth()
    poses = plan_poses(truth, max(pose_counts), seed=seed)
    renderer = Renderer(truth)
    lines = ['poses | focal max % | centre max px | R_0i max deg | imu_to_camera deg | '
             'tilt err deg | fit s']
    with tempfile.TemporaryDirectory() as tmp:
        write_dataset(tmp, truth, poses, renderer, seed=seed)
        names = sorted(os.listdir(tmp))
        for count in track(pose_counts, 'rig study'):
            sub = os.path.join(tmp, f'first{count}')
            os.makedirs(sub)
            for name in names[:count]:
                os.symlink(os.path.join(tmp, name), os.path.join(sub, name))
            result = calibrate_directory(sub, truth.board)
            e = errors(result, truth)
            lines.append(f'{count:5d} | {e["focal_pct"]:11.3f} | {e["centre_px"]:13.2f} | '
                         f'{e["R_0i_deg"]:12.4f} | {e["imu_to_camera_deg"]:17.4f} | '
                         f'{e["tilt_error_deg"]:12.4f} | {result.fit.fit_time_s:5.2f}')
    lines.append('targets (30 poses): focal 0.3 %, centre 2 px, R_0i 0.05 deg, '
                 'imu_to_camera 0.05 deg')
    return lines
