"""
Small ROS 2 helpers shared by the nodes (the only place besides nodes importing rclpy).

- :mod:`.runner`   -- ``run(factory, executor=...)``: ``main()`` of every node; executor
  (events/single/multi, ``ACCELCAL_EXECUTOR``), SIGINT/SIGTERM, fatal errors as one line.
- :mod:`.params`   -- declare :class:`~accelcal_ros.paramspec.ParamSpec` lists with
  statically typed descriptors, coercion and an all-or-nothing set-parameters callback.
- :mod:`.qos`      -- the QoS of high-rate IMU subscriptions.
- :mod:`.images`   -- sensor_msgs/Image <-> numpy (the part of cv_bridge we need).
- :mod:`.stamps`   -- builtin_interfaces/Time <-> float seconds.
- :mod:`.stamp_sync`, :mod:`.pointcloud2` -- stamp matching, PointCloud2 <-> numpy.
"""
