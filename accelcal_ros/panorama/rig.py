"""
Camera rig of the panorama: the rig file lives on the shared floor, :mod:`accelcal_ros.camera.rig`.

Re-exported here under the names the panorama has always used (``Camera`` is
:class:`~accelcal_ros.camera.rig.RigCamera`).
"""
from accelcal_ros.camera.rig import (CAMERA_ENTRY_KEYS, camera_from_mapping, load_rig,
                                     REFERENCE_TOLERANCE, resolve_imu_to_camera, Rig,
                                     rig_from_mapping, rig_to_mapping, RigCamera, ring_rig,
                                     save_rig)

Camera = RigCamera

__all__ = ['CAMERA_ENTRY_KEYS', 'Camera', 'camera_from_mapping', 'load_rig',
           'REFERENCE_TOLERANCE', 'resolve_imu_to_camera', 'Rig', 'rig_from_mapping',
           'rig_to_mapping', 'RigCamera', 'ring_rig', 'save_rig']
