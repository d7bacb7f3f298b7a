"""
``accelcal sample-data DIR``: the simulated recordings the README's commands use.

Every journey of the README starts from a recording a user would make on the robot
(``ros2 bag record ...``). This package writes simulated stand-ins for all of them, under
the README's names, so that every ``accelcal`` command of the README runs as printed in
``DIR`` (``test/test_readme_commands.py`` does exactly that):

=====================  ==================================================================
``rosbag2_imu``        IMU bag (mcap, ``/imu/data_raw``, 100 Hz): the ADXL345 simulator
                       turned through 24 still dwells of 3 s (calibration journey)
``rec.csv``            the same kind of recording as CSV ``t,ax,ay,az`` (s, m/s^2)
``rosbag2_rig``        rig calibration bag: 3 cameras (``/camN/image_raw``, 400x300) of a
                       9x6 chessboard (25 mm squares) in 15 still poses, ``/imu/data_raw``
``rosbag2_drive``      a drive: the same 3 cameras looking at a rendered scene while the
                       rig rolls and pitches, ``/imu/data_raw``, a VLP-16
                       (``/velodyne_points``) and ``/odometry/filtered``
``img0..2.png``        the same cameras, rig at roll 0, pitch 15 deg (``accelcal stitch``)
``rosbag2_p2p``        one camera (``/camera/image_raw``, ``/camera/camera_info``) seeing
                       two emitters 1 m apart, ``/imu/data_raw``
``rosbag2_boresight``  paper B's 15-position protocol: ``/imu/data`` and ``/velodyne_points``
``boresight_positions``  the same protocol as files: ``posNN.pcd`` + ``posNN_imu.csv``
``scan.pcd``           one moving-platform scan (absolute per-point ``timestamp``)
``poses.csv``          the platform poses ``t,x,y,z,qx,qy,qz,qw`` around that scan
``drive_trajectory.csv``  a GNSS/INS trajectory ``t,lat,lon,h,roll,pitch,yaw`` (10 s at
                       55.75 N 37.6 E, UTM 37N) with ``drive_scan.pcd`` (targets at known
                       geodetic coordinates and VLP-16 revolutions), ``drive_boresight.yaml``
``rosbag2_ins``        the same drive as an INS would record it: ``/gnss/fix``
                       (NavSatFix, a few NO_FIX), ``/ins/odom``, ``/velodyne_points``
=====================  ==================================================================

The scanner's boresight and lever arm are the same in every LiDAR recording (the drive's
truth is what ``accelcal boresight`` finds), and the drive's cameras are the rig bag's
cameras, so the README's chain (calibrate -> rig-calibrate -> stitch, boresight ->
georeference) holds together. This is the dispatcher's level: like :mod:`accelcal_ros.cli`
and :mod:`accelcal_ros.demo` it composes the features' simulators.
"""
import os
from typing import Callable, Dict, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError

#: (name, what) of every journey, in the README's order; each writes the files listed
JOURNEYS: Tuple[Tuple[str, str], ...] = (
    ('imu', 'rosbag2_imu, rec.csv'),
    ('rig', 'rosbag2_rig'),
    ('drive', 'rosbag2_drive, img0.png, img1.png, img2.png'),
    ('p2p', 'rosbag2_p2p'),
    ('lidar', 'rosbag2_boresight, boresight_positions, scan.pcd, poses.csv'),
    ('map', 'drive_trajectory.csv, drive_scan.pcd, drive_boresight.yaml, rosbag2_ins'),
)


def journey_outputs(name: str) -> List[str]:
    """Return the file and folder names journey ``name`` writes."""
    for journey, outputs in JOURNEYS:
        if journey == name:
            return [item.strip() for item in outputs.split(',')]
    raise InputError(f'no sample-data journey {name!r}; journeys: '
                     f'{", ".join(j for j, _ in JOURNEYS)}')


def _writers() -> Dict[str, Callable[[str], object]]:
    from accelcal_ros.lidar.geo_sim import write_sample as write_map
    from accelcal_ros.sample_data import cameras, imu, lidar, p2p

    return {'imu': imu.write, 'rig': cameras.write_rig_bag, 'drive': cameras.write_drive,
            'p2p': p2p.write, 'lidar': lidar.write, 'map': write_map}


def write_sample_data(directory: str, only: Optional[Sequence[str]] = None,
                      log: Callable[[str], None] = print) -> List[str]:
    """
    Write the journeys ``only`` (default: all) into ``directory``; return the names written.

    Refuses (before writing anything) when one of the names exists already: sample data
    never replaces a user's recording.
    """
    names = [j for j, _ in JOURNEYS] if not only else list(only)
    outputs = [out for name in names for out in journey_outputs(name)]
    if os.path.exists(directory) and not os.path.isdir(directory):
        raise InputError(f'{directory} exists and is not a directory')
    existing = [out for out in outputs if os.path.lexists(os.path.join(directory, out))]
    if existing:
        raise InputError(f'{directory} already holds {", ".join(existing)}: sample-data '
                         'never replaces a file; give another directory or remove them')
    os.makedirs(directory, exist_ok=True)
    writers = _writers()
    for name in names:
        log(f'{name}: writing {", ".join(journey_outputs(name))}')
        writers[name](directory)
    return outputs
