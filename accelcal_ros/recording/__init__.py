"""
Recordings in and out: rosbag2 (sqlite3, mcap) and ROS 1 bags without a ROS install.

- :mod:`.bag`      -- :class:`~.bag.BagReader`: one streaming reader for every bag format
  (messages in receive-time order across topics, header stamp and receive time both
  kept), topic selection by type, clear errors for missing, corrupt or truncated bags.
- :mod:`.convert`  -- deserialised messages -> numpy (Imu, PointCloud2, Odometry, Image,
  CompressedImage, Vector3Stamped attitude, CameraInfo).
- :mod:`.streams`  -- whole streams the offline commands need (IMU arrays, attitude, poses)
  with stamp checks (backwards, jumps, header far from receive time).
- :mod:`.writer`   -- :class:`~.writer.BagWriter` (rosbag2 mcap/sqlite3, ROS 1) and the
  driver's ``imu/data_raw`` messages (sensor-data QoS).
- :mod:`.progress` -- a progress bar on a terminal, silent otherwise.

Built on ``rosbags`` (pure Python); nothing here imports rclpy.
"""
