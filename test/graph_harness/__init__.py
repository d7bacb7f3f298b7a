"""Test harness: node processes in a real ROS 2 graph, probed with rclpy (not installed)."""
