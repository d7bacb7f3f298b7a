"""
The Fast DDS profile of the image nodes: a shared-memory segment large enough for frames.

Fast DDS (Jazzy's default RMW) keeps a 0.5 MB shared-memory segment per participant; a
larger message (a 640x480 bgr8 frame is 0.9 MB, a panorama several MB) goes over UDP
loopback in 64 kB fragments, and at camera rates fragments are lost, so keep-last readers
lose whole frames. The package ships ``config/fastdds_large_shm.xml`` (a 128 MB segment);
:func:`use_large_message_profile` points this process at it before ``rclpy.init`` unless
the user chose a profile or another RMW. Camera drivers and viewers need the same
``FASTRTPS_DEFAULT_PROFILES_FILE`` for their frames to go through shared memory too.
"""
import os
from typing import Optional

PROFILE_FILE = 'fastdds_large_shm.xml'
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE')


def large_message_profile_path() -> Optional[str]:
    """Return the installed ``config/fastdds_large_shm.xml``, or None when it is missing."""
    try:
        from ament_index_python.packages import (get_package_share_directory,
                                                 PackageNotFoundError)
    except ImportError:  # pragma: no cover - ament_index_python ships with rclpy
        return None
    try:
        share = get_package_share_directory('accelcal_ros')
    except PackageNotFoundError:
        return None
    path = os.path.join(share, 'config', PROFILE_FILE)
    return path if os.path.isfile(path) else None


def use_large_message_profile() -> Optional[str]:
    """
    Point this process's Fast DDS at the shipped profile; return its path (None: unchanged).

    Nothing changes when a profile variable is set already (the user's choice) or when
    ``RMW_IMPLEMENTATION`` names another middleware. Call before ``rclpy.init``.
    """
    rmw = os.environ.get('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    if rmw not in ('', 'rmw_fastrtps_cpp') or any(os.environ.get(v) for v in PROFILE_VARIABLES):
        return None
    path = large_message_profile_path()
    if path is not None:
        os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = path
    return path
