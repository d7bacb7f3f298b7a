"""
Scenario drivers of the scanner simulator: publish its IMU, scans and odometry over ROS.

The ROS side of :mod:`accelcal_ros.lidar.scanner_sim` (which stays pure): message
builders (sensor_msgs/Imu in m/s^2 and rad/s, PointCloud2 with per-point time,
nav_msgs/Odometry) and drivers that play paper B's static protocol or a moving platform
in real time through publishers of a given rclpy node. Used by the demo (``run-demo``
stage ``lidar``), the graph tests and ``benchmarks/stress_lidar_capture.py``.
"""
import time

from accelcal_ros.rosutil.pointcloud2 import array_to_pointcloud2
from accelcal_ros.rosutil.stamps import seconds_to_stamp
from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu, PointCloud2, PointField
from std_msgs.msg import Header
from std_srvs.srv import Trigger


def imu_msg(t, accel, gyro, frame_id='imu_link'):
    """Return a sensor_msgs/Imu with specific force (m/s^2) and rate (rad/s)."""
    msg = Imu()
    msg.header.stamp = seconds_to_stamp(t, Time)
    msg.header.frame_id = frame_id
    msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = \
        (float(v) for v in accel)
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = \
        (float(v) for v in gyro)
    msg.orientation_covariance[0] = -1.0
    return msg


def cloud_msg(cloud, stamp_s, frame_id='lidar_link'):
    """Return a PointCloud2 of a structured cloud stamped ``stamp_s``."""
    header = Header(frame_id=frame_id, stamp=seconds_to_stamp(stamp_s, Time))
    return array_to_pointcloud2(cloud, PointCloud2, PointField, header)


def odom_msg(t, position, quat_xyzw, frame_id='map', child_frame_id='base_link'):
    """Return a nav_msgs/Odometry pose of the body (IMU) in the navigation frame."""
    msg = Odometry()
    msg.header.stamp = seconds_to_stamp(t, Time)
    msg.header.frame_id = frame_id
    msg.child_frame_id = child_frame_id
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    p.x, p.y, p.z = (float(v) for v in position)
    q.x, q.y, q.z, q.w = (float(v) for v in quat_xyzw)
    return msg


def wait_for_subscribers(publishers, timeout=15.0):
    """Wait until every publisher is matched (the node under test is up), then a bit."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if all(p.get_subscription_count() > 0 for p in publishers):
            break
        time.sleep(0.05)
    time.sleep(0.3)


PACKETS_PER_REVOLUTION = 20
"""Scans are sent as 1/20 revolutions (1440 points, ~32 kB in, ~55 kB georeferenced out):
each fits one UDP datagram, so DDS neither fragments nor loses them in bursts."""


def drive_static_positions(node, protocol, indices, move_s=0.6, still_s=1.6, imu_hz=50.0,
                           t0=1000.0, say=None, prefix=''):
    """
    Publish IMU + scans for the chosen positions in real time (handling between them).

    Each still period carries two revolutions, sent reliable as packets of 1/20 revolution
    (``PACKETS_PER_REVOLUTION``); start the node with ``points_reliable: true`` and
    ``clouds_per_capture: 20``.
    """
    imu_pub = node.create_publisher(Imu, prefix + 'imu/data_raw', qos_profile_sensor_data)
    pts_pub = node.create_publisher(PointCloud2, prefix + 'points',
                                    10 * PACKETS_PER_REVOLUTION)  # a slow reader catches up
    rng = np.random.default_rng(0)
    wait_for_subscribers([imu_pub, pts_pub])
    start = time.monotonic()
    t_sim = t0
    for k in indices:
        pos = protocol[k]
        if say:
            say(f'  rig to {pos.name} (gravity in IMU frame '
                f'{np.round(pos.gravity_true_imu, 2).tolist()} m/s^2)')
        quarter = np.array_split(np.arange(len(pos.cloud)), PACKETS_PER_REVOLUTION)
        packets = [cloud_msg(pos.cloud[q], 0.0) for q in quarter] * 2
        phase_end = t_sim + move_s + still_s
        next_cloud = t_sim + move_s + 0.6
        while t_sim < phase_end:
            moving = t_sim < phase_end - still_s
            gyro = rng.normal(0, 0.3 if moving else 0.001, 3)
            accel = pos.gravity_true_imu + rng.normal(0, 0.5 if moving else 0.02, 3)
            imu_pub.publish(imu_msg(t_sim, accel, gyro))
            if not moving and t_sim >= next_cloud and packets:
                msg = packets.pop(0)
                msg.header.stamp = seconds_to_stamp(t_sim, Time)
                pts_pub.publish(msg)
                next_cloud += 0.4 / PACKETS_PER_REVOLUTION
            t_sim += 1.0 / imu_hz
            lag = (t_sim - t0) - (time.monotonic() - start)
            if lag > 0:
                time.sleep(lag)
    node.destroy_publisher(imu_pub)
    node.destroy_publisher(pts_pub)


def finish_calibration(call, name='lidar_calibration', patience_s=10.0):
    """
    Call ``<name>/finish`` until it succeeds or ``patience_s`` passed; return the answer.

    ``call(srv_type, service_name, timeout=...)`` returns a service response (as the
    graph harness's ``Graph.call`` does).

    A node that fell behind (starved of CPU) is still working through its queued scans
    and IMU samples when the driving ends, so "only N positions captured" can turn into
    a result a few seconds later, as it would for an operator who asks again.
    """
    deadline = time.monotonic() + patience_s
    while True:
        response = call(Trigger, f'{name}/finish', timeout=30.0)
        waiting = ('positions captured' in response.message
                   or 'nothing captured' in response.message)
        if response.success or not waiting or time.monotonic() > deadline:
            return response
        time.sleep(1.0)


def drive_moving_platform(node, scene, scan_hz=40.0, reliable=False, pace=1.0, prefix=''):
    """
    Publish odometry (pose stream) and scans of a moving scene in real time.

    Scans go out as ``scan_hz`` packets (40 Hz: quarter revolutions, ~160 kB; the
    georeferenced output is ~270 kB per packet), best effort as most drivers publish;
    ``reliable`` publishes them reliable, for a node started with ``points_reliable: true``.
    ``prefix`` is put before the topic names (the demo remaps the nodes to its own names,
    so other graphs in the same ROS domain cannot interfere). ``pace`` < 1 plays
    the recording slower than real time (stamps unchanged).
    """
    odom_pub = node.create_publisher(Odometry, prefix + 'odom', 500)
    pts_pub = node.create_publisher(PointCloud2, prefix + 'points',
                                    20 if reliable else qos_profile_sensor_data)
    wait_for_subscribers([odom_pub, pts_pub])
    poses = scene.poses
    rel = scene.cloud['time'].astype(float)
    n_scans = int(np.ceil((rel.max() + 1e-9) * scan_hz))
    k_pose = 0
    start = time.monotonic()
    for s in range(n_scans):
        lo, hi = s / scan_hz, (s + 1) / scan_hz
        stamp = scene.scan_start_s + lo
        end = scene.scan_start_s + hi
        while k_pose < len(poses.t) and poses.t[k_pose] <= end + 0.02:
            odom_pub.publish(odom_msg(poses.t[k_pose], poses.position[k_pose],
                                      poses.quat_xyzw[k_pose]))
            k_pose += 1
        part = scene.cloud[(rel >= lo) & (rel < hi)].copy()
        part['time'] = part['time'] - np.float32(lo)
        pts_pub.publish(cloud_msg(part, stamp))
        lag = hi / pace - (time.monotonic() - start)
        if lag > 0:
            time.sleep(lag)
    while k_pose < len(poses.t):
        odom_pub.publish(odom_msg(poses.t[k_pose], poses.position[k_pose],
                                  poses.quat_xyzw[k_pose]))
        k_pose += 1
    return n_scans
