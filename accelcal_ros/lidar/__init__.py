"""
LiDAR-IMU boresight calibration and georeferenced point clouds (paper B).

Pure core: :mod:`.pcd`, :mod:`.ply` (files), :mod:`.imu_log`, :mod:`.poses`,
:mod:`.static_segments`, :mod:`.plane_fit` (floor by MSAC), :mod:`.boresight` (Wahba),
:mod:`.georef`, :mod:`.error_budget` (paper B eq. 1), :mod:`.scanner_sim` (VLP-16 in a
room). Nodes: :mod:`.calibration_node` (``lidar_calibration``) and
:mod:`.assembler_node` (``cloud_assembler``).
"""
