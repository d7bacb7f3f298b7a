"""
Demo stage ``lidar``: paper B's boresight calibration and a georeferenced point cloud.

1. Simulates paper B's 15-position protocol (VLP-16 in a room, known boresight), writes
   it as ``posNN.pcd`` + ``posNN_imu.csv`` and runs ``accelcal boresight`` on it (the CLI
   core), printing the recovered angles against the truth; draws Fig. 10 (per-position
   errors) as ``lidar_boresight_errors.png``.
2. Starts the ``lidar_calibration`` node and feeds it a few positions (probe publishes
   sensor_msgs/Imu and PointCloud2); it captures them automatically and ``finish``
   solves and writes the YAML.
3. Starts the ``cloud_assembler`` node with that boresight and feeds it a moving platform
   (PointCloud2 scans with per-point time + nav_msgs/Odometry); prints what it publishes
   and checks the points against the scene; saves ``lidar_georeferenced.ply``.

The helpers that build and publish the messages are reused by the graph tests.
"""
import os
import time

from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.rosutil.pointcloud2 import array_to_pointcloud2, pointcloud2_to_array
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


def cloud_msg(cloud, stamp_s, frame_id='velodyne'):
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


def drive_static_positions(graph, protocol, indices, move_s=0.6, still_s=1.6, imu_hz=50.0,
                           t0=1000.0, say=None, prefix=''):
    """
    Publish IMU + scans for the chosen positions in real time (handling between them).

    Each still period carries two revolutions, sent reliable as packets of 1/20 revolution
    (``PACKETS_PER_REVOLUTION``); start the node with ``points_reliable: true`` and
    ``clouds_per_capture: 20``.
    """
    imu_pub = graph.node.create_publisher(Imu, prefix + 'imu/data_raw', qos_profile_sensor_data)
    pts_pub = graph.node.create_publisher(PointCloud2, prefix + 'points',
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
    graph.node.destroy_publisher(imu_pub)
    graph.node.destroy_publisher(pts_pub)


def finish_calibration(graph, name='lidar_calibration', patience_s=10.0):
    """
    Call ``<name>/finish`` until it succeeds or ``patience_s`` passed; return the answer.

    A node that fell behind (starved of CPU) is still working through its queued scans
    and IMU samples when the driving ends, so "only N positions captured" can turn into
    a result a few seconds later, as it would for an operator who asks again.
    """
    deadline = time.monotonic() + patience_s
    while True:
        response = graph.call(Trigger, f'{name}/finish', timeout=30.0)
        if response.success or 'positions captured' not in response.message \
                or time.monotonic() > deadline:
            return response
        time.sleep(1.0)


def drive_moving_platform(graph, scene, scan_hz=40.0, reliable=False, pace=1.0, prefix=''):
    """
    Publish odometry (pose stream) and scans of a moving scene in real time.

    Scans go out as ``scan_hz`` packets (40 Hz: quarter revolutions, ~160 kB; the
    georeferenced output is ~270 kB per packet), best effort as most drivers publish;
    ``reliable`` publishes them reliable, for a node started with ``points_reliable: true``.
    ``prefix`` is put before the topic names (the demo remaps the nodes to its own names,
    so other graphs in the same ROS domain cannot interfere). ``pace`` < 1 plays
    the recording slower than real time (stamps unchanged).
    """
    odom_pub = graph.node.create_publisher(Odometry, prefix + 'odom', 500)
    pts_pub = graph.node.create_publisher(PointCloud2, prefix + 'points',
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


def run(ctx):
    """Run the stage (see the module docstring)."""
    from accelcal_ros.fileio import dump_yaml, write_text_atomic
    from accelcal_ros.frames import rpy_radians_from_rotation
    from accelcal_ros.lidar.boresight import rotation_angle_deg
    from accelcal_ros.lidar.calibrate_dir import (calibrate_directory, plot_errors,
                                                  report_lines, write_result)
    from accelcal_ros.lidar.cloud import write_cloud

    say = ctx.say
    out = ctx.out_dir
    truth = sim.default_boresight()
    say('paper B protocol: VLP-16 (16 rings +-15 deg, 0.2 deg steps, 3 cm noise) in a '
        '10 x 8 x 3 m room, 15 static positions (X -90..90 deg by 45, Y -90/0/90 deg)')
    protocol = sim.simulate_protocol(truth, seed=7)
    data_dir = os.path.join(out, 'lidar_protocol')
    sim.write_protocol(data_dir, protocol)
    t = time.monotonic()
    result = calibrate_directory(data_dir)   # no prior: the floor is found by consistency
    say(f'$ accelcal boresight {data_dir} -o lidar_boresight.yaml   '
        f'({time.monotonic() - t:.1f} s)')
    for line in report_lines(result):
        say('  ' + line)
    yaml_path = os.path.join(out, 'lidar_boresight.yaml')
    write_result(yaml_path, result)
    true_rpy = np.degrees(rpy_radians_from_rotation(truth))
    err = rotation_angle_deg(result.rotation, truth)
    say(f'truth rpy {np.round(true_rpy, 4).tolist()} deg -> boresight error {err:.4f} deg '
        f'(target < 0.05 deg; paper B: 0.3 deg mean per position)')
    png = os.path.join(out, 'lidar_boresight_errors.png')
    plot_errors(png, result)
    say(f'wrote {yaml_path} and {png}')

    say('--- lidar_calibration node (auto capture on rest, Trigger finish) ---')
    node_yaml = os.path.join(out, 'lidar_boresight_node.yaml')
    graph = ctx.graph
    topics = {'points': 'lidar_demo/points', 'imu/data_raw': 'lidar_demo/imu/data_raw',
              'odom': 'lidar_demo/odom', 'points_georef': 'lidar_demo/points_georef'}
    proc = graph.start('lidar_calibration', remaps=topics, params={
        'output_file': node_yaml, 'prior_rpy_deg': [0.0, 45.0, 0.0], 'min_static_s': 0.5,
        'min_positions': 3, 'points_reliable': True,
        'clouds_per_capture': PACKETS_PER_REVOLUTION})
    picks = [1, 2, 5, 7, 12] if not ctx.quick else [2, 7, 12]
    drive_static_positions(graph, protocol, picks, still_s=2.4, say=say, prefix='lidar_demo/')
    response = finish_calibration(graph)
    time.sleep(0.2)
    for line in proc.output().splitlines():
        if 'captured' in line:
            say('  [lidar_calibration] ' + line.split(']: ')[-1])
    say(f'  finish -> success={response.success}: {response.message}')
    proc.stop()
    if not response.success:
        raise RuntimeError(f'lidar_calibration finish failed: {response.message}')

    say('--- cloud_assembler node on a moving platform (odometry 200 Hz, VLP-16 at 10 Hz '
        'sent as 40 Hz packets, played at half speed) ---')
    scene = sim.simulate_moving_platform(1.5 if ctx.quick else 3.0, seed=1)
    bs_path = os.path.join(out, 'lidar_platform_boresight.yaml')
    write_text_atomic(bs_path, dump_yaml({'R': scene.boresight.ravel().tolist()}))
    ply = os.path.join(out, 'lidar_georeferenced.ply')
    graph.start('cloud_assembler', remaps=topics, params={
        'boresight_file': bs_path, 'lever_arm_m': scene.lever_arm_m.tolist(),
        'output_file': ply, 'queue_depth': 50})
    collector = graph.collect(PointCloud2, 'lidar_demo/points_georef', 50)
    n_scans = drive_moving_platform(graph, scene, pace=0.5,  # half real time: 2 busy cores
                                    prefix='lidar_demo/')
    deadline = time.monotonic() + 10.0
    while len(collector.snapshot()[0]) < n_scans and time.monotonic() < deadline:
        time.sleep(0.1)
    msgs = collector.snapshot()[0]
    all_pts = []
    for k, msg in enumerate(msgs):
        cloud = pointcloud2_to_array(msg)
        pts = np.stack([cloud['x'], cloud['y'], cloud['z']], axis=1)
        all_pts.append(pts)
        if len(pts) and (k % 20 == 0 or k == len(msgs) - 1):
            d = scene.room.surface_distance(pts)
            say(f'  points_georef #{k + 1}: {len(pts)} points in frame {msg.header.frame_id}, '
                f'distance to the hall surfaces rms {np.sqrt(np.mean(d ** 2)) * 100:.1f} cm')
    if all_pts:
        pts = np.vstack(all_pts)
        d = scene.room.surface_distance(pts)
        say(f'received {len(msgs)} of {n_scans} scans, {len(pts)} points; rms distance to the '
            f'known geometry {np.sqrt(np.mean(d ** 2)) * 100:.2f} cm (3 cm range noise)')
    response = graph.call(Trigger, 'cloud_assembler/save', timeout=20.0)
    say(f'  save -> {response.message}')
    if not response.success:
        from accelcal_ros.lidar.cloud import make_cloud

        write_cloud(ply, make_cloud(np.vstack(all_pts) if all_pts else np.zeros((0, 3)),
                                    double=True))
