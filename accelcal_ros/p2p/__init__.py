"""
Perspective-2-Point positioning with the accelerometer's vertical (paper A, eq. 8).

- :mod:`.solver`  -- closed-form P2P with known vertical (single and vectorised batch).
- :mod:`.beacons` -- detection of the two emitters in an image (sub-pixel, undistorted).
- :mod:`.render`  -- rendered ground-truth images of two emitters at known poses.
- :mod:`.study`   -- paper A Table 2 Monte Carlo (``accelcal study p2p``).
- :mod:`.node`    -- the ``p2p`` ROS 2 node (thin wiring only).
"""
