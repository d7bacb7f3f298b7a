"""
Levelled spherical (and cylindrical) video panorama from a calibrated camera rig.

Paper A (Kalinkin et al. 2020), "Spherical panorama sector": several cameras with known
intrinsics ``K_i``, distortion ``D_i`` and rotations ``R_0i`` relative to the reference
camera, plus the reference camera's roll and pitch from the accelerometer, give a
levelled panorama at video rate.

- :mod:`.projection` -- panorama pixel <-> ray (spherical / cylindrical), frames contract.
- :mod:`.rig`        -- rig file loading and validation.
- :mod:`.lookup`     -- camera choice (eq. 6), projection (eq. 7 and the projection step),
  exact and fast (coarse grid + interpolation) lookup maps.
- :mod:`.stitch`     -- :class:`~.stitch.Stitcher`: one ``cv2.remap`` per frame.
- :mod:`.render`     -- synthetic equirectangular scenes and camera views (ground truth).
- :mod:`.horizon_study` -- ``accelcal study horizon`` (paper A, Fig. 6).
"""
