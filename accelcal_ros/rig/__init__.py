"""
Rig calibration: camera intrinsics, rig rotations ``R_0i`` and ``imu_to_camera``.

Chessboard views taken in still poses of the rig give each camera's intrinsics, the
rotations between cameras (joint least squares over all views) and, with the
accelerometer's gravity in each pose, the IMU-to-reference-camera rotation (issue 12;
J. Lobo, J. Dias, IJRR 26(6), 2007).
"""
