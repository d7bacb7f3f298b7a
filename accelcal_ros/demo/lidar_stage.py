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

The scenario drivers that publish the simulated messages live beside the simulator, in
:mod:`accelcal_ros.lidar.scanner_sim_ros`.
"""
import os
import time

from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.scanner_sim_ros import (drive_moving_platform, drive_static_positions,
                                                finish_calibration, PACKETS_PER_REVOLUTION)
from accelcal_ros.rosutil.pointcloud2 import pointcloud2_to_array
import numpy as np
from sensor_msgs.msg import PointCloud2
from std_srvs.srv import Trigger


def run(ctx):
    """Run the stage (see the module docstring)."""
    from accelcal_ros.fileio import write_text_atomic
    from accelcal_ros.textformats import dump_yaml
    from accelcal_ros.frames import rpy_radians_from_rotation
    from accelcal_ros.lidar.calibrate_dir import (calibrate_directory, plot_errors,
                                                  report_lines, write_result)
    from accelcal_ros.lidar.cloud import write_cloud
    from accelcal_ros.lidar.wahba import rotation_angle_deg

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
    say('$ ros2 service call /lidar_calibration/start std_srvs/srv/Trigger')
    started = graph.call(Trigger, 'lidar_calibration/start', timeout=30.0)
    say(f'  -> success={started.success}: {started.message}')
    picks = [1, 2, 5, 7, 12] if not ctx.quick else [2, 7, 12]
    drive_static_positions(graph.node, protocol, picks, still_s=2.4, say=say, prefix='lidar_demo/')
    response = finish_calibration(graph.call)
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
    n_scans = drive_moving_platform(graph.node, scene, pace=0.5,  # half real time: 2 busy cores
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
