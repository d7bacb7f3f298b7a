"""
Levelled spherical (and cylindrical) video panorama from a calibrated camera rig.

Paper A (Kalinkin et al. 2020), "Spherical panorama sector": several cameras with known
intrinsics ``K_i``, distortion ``D_i`` and rotations ``R_0i`` relative to the reference
camera, plus the reference camera's roll and pitch from the accelerometer, give a
levelled panorama at video rate.

- :mod:`.projection` -- panorama pixel <-> ray (spherical / cylindrical), frames contract.
- :mod:`.rig`        -- rig file loading and validation (cameras: :mod:`accelcal_ros.camera`).
- :mod:`.rig_projection` -- tilt (eq. 7), camera choice (eq. 6) and projection of rays.
- :mod:`.mosaic`     -- where each camera image sits in the mosaic that is remapped.
- :mod:`.maps`       -- exact and blend lookup maps (every pixel evaluated).
- :mod:`.lookup`     -- the fast lookup builder (coarse grid + interpolation + exact seams).
- :mod:`.stitch`     -- :class:`~.stitch.Stitcher`: one ``cv2.remap`` per frame.
- :mod:`.render`     -- synthetic equirectangular scenes and camera views (ground truth).
- :mod:`.horizon_study` -- ``accelcal study horizon`` (paper A, Fig. 6).
- :mod:`.view`       -- levelled pinhole views (personal regions of interest); :mod:`.view_set`
  named views over one mosaic; :mod:`.roi_node` the stitcher's ``roi/<name>`` topics;
  :mod:`.serve` ``accelcal serve`` (browser); :mod:`.roi_study` ``accelcal study roi``.
"""
