"""
Small ROS 2 helpers shared by the nodes (the only place besides nodes importing rclpy).

- :mod:`.params`   -- declare :class:`~accelcal_ros.paramspec.ParamSpec` lists with
  descriptors and a validating set-parameters callback.
- :mod:`.images`   -- sensor_msgs/Image <-> numpy (the part of cv_bridge we need).
- :mod:`.stamps`   -- builtin_interfaces/Time <-> float seconds.
"""
