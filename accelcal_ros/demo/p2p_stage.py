"""
Demo stage ``p2p``: camera pose from two emitters and the simulated IMU's vertical.

``imu_driver`` (sim backend, one static pose: the camera body rolled 3 deg and pitched
15 deg down) feeds the ``attitude`` node (calibrated with the sim's true parameters), which
feeds ``p2p``. The probe plays the camera: it renders the two emitters (0.5 m apart along
object y) at known poses on a 4 m circle, 1.07 m above them, with the camera heading
sweeping through 180 deg (where a tan(yaw/2) solver breaks down), and publishes the
images and camera_info. The readout compares ``pose``/``yaw`` with the rendered truth.
If ``attitude`` is not installed, ``sim/attitude_truth`` is remapped to ``attitude``.
"""
import time

from accelcal_ros.camera import CameraModel
from accelcal_ros.p2p import render
from accelcal_ros.p2p.solver import yaw_from_rotation
from accelcal_ros.rosutil.images import array_to_image_msg
from accelcal_ros.rosutil.stamps import stamp_to_seconds
from accelcal_ros.sensor.model import PAPER_K500_BIAS, PAPER_K500_SCALE
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, Vector3Stamped
from graph_harness.graph import executable
import numpy as np
from scipy.spatial.transform import Rotation
from sensor_msgs.msg import CameraInfo, Image

ROLL_DEG, PITCH_DEG = 3.0, 15.0
EMITTERS = [0.0, -0.25, 0.0, 0.0, 0.25, 0.0]
RADIUS_M = 4.0


def truth_at(azimuth_deg):
    """Return ``(R, t, camera_position)`` of the camera on the circle at ``azimuth_deg``."""
    azimuth = np.radians(azimuth_deg)
    height = RADIUS_M * np.tan(np.radians(PITCH_DEG))
    position = np.array([RADIUS_M * np.cos(azimuth), RADIUS_M * np.sin(azimuth), height])
    yaw = azimuth + np.pi                                   # look back at the emitters
    rotation, translation = render.pose_from_camera_attitude(
        np.radians(ROLL_DEG), np.radians(PITCH_DEG), yaw, position)
    return rotation, translation, position


def run(ctx):
    """Run imu_driver + attitude + p2p; publish rendered frames; print poses against truth."""
    graph = ctx.graph
    camera = CameraModel.from_fov(1280, 960, 60.0,
                                  dist_coeffs=[-0.12, 0.03, 0.0, 0.0, 0.0])
    try:
        executable('attitude')
        have_attitude = True
    except FileNotFoundError:
        have_attitude = False
    ctx.say(f'$ ros2 run accelcal_ros imu_driver --ros-args -p backend:=sim '
            f'-p sim.poses_deg:="[{ROLL_DEG}, {PITCH_DEG}]" -p sim.dwell_s:=3600.0')
    graph.start('imu_driver', {'backend': 'sim', 'rate_hz': 100.0,
                               'sim.poses_deg': [ROLL_DEG, PITCH_DEG], 'sim.dwell_s': 3600.0,
                               'sim.move_s': 0.0})
    remaps = None
    if have_attitude:
        ctx.say('$ ros2 run accelcal_ros attitude --ros-args -p calibration.scale:=<sim truth> '
                '-p calibration.bias:=<sim truth> -p time_constant_s:=0.3')
        graph.start('attitude', {'calibration.scale': list(PAPER_K500_SCALE),
                                 'calibration.bias': list(PAPER_K500_BIAS),
                                 'time_constant_s': 0.3})
    else:
        remaps = {'attitude': 'sim/attitude_truth'}
        ctx.say('(attitude node not installed: p2p uses sim/attitude_truth remapped to '
                'attitude)')
    ctx.say(f'$ ros2 run accelcal_ros p2p --ros-args -p emitters:="{EMITTERS}" '
            f'-p threshold:=60 -p image_qos:=reliable')
    proc = graph.start('p2p', {'emitters': EMITTERS, 'threshold': 60,
                               'image_qos': 'reliable'}, remaps=remaps)

    node = graph.node
    image_pub = node.create_publisher(Image, 'image', 5)      # reliable, as most drivers
    info_pub = node.create_publisher(CameraInfo, 'camera_info', 10)
    poses = graph.collect(PoseStamped, 'pose', 10)
    yaws = graph.collect(Vector3Stamped, 'yaw', 10)
    attitude = graph.collect(Vector3Stamped, 'attitude' if have_attitude
                             else 'sim/attitude_truth')
    diag = graph.collect(DiagnosticArray, '/diagnostics', 10)
    attitude.wait_for(1, timeout=30.0)
    deadline = time.monotonic() + 20.0
    while image_pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.1)       # p2p subscribed: no frame is lost to discovery

    info = CameraInfo()
    info.header.frame_id = 'camera_optical'
    info.width, info.height = camera.width, camera.height
    info.k = [float(v) for v in camera.camera_matrix.reshape(-1)]
    info.d = [float(v) for v in camera.dist_coeffs]
    info.distortion_model = 'plumb_bob'
    info.p = [info.k[0], 0.0, info.k[2], 0.0, 0.0, info.k[4], info.k[5], 0.0,
              0.0, 0.0, 1.0, 0.0]

    duration = 12.0 if ctx.quick else 24.0
    period = 0.2
    truths = {}
    ctx.say('camera: 1280x960, 60 deg, plumb_bob D; emitters M1 (0, -0.25, 0), M2 (0, 0.25, 0) '
            'm; camera 4 m away, 1.07 m above, heading sweeping 150 -> 210 deg')
    ctx.say(f'{"t s":>5} {"true yaw":>9} {"p2p yaw":>9} {"err deg":>8} {"true range":>10} '
            f'{"p2p range":>9} {"err %":>7} {"camera position (object frame) m":>34}')
    start = time.monotonic()
    shown = 0
    frame = 0
    while time.monotonic() - start < duration:
        phase = (time.monotonic() - start) / duration
        azimuth = -30.0 + 60.0 * phase
        rotation, translation, position = truth_at(azimuth)
        image, _, _ = render.render_emitters(np.reshape(EMITTERS, (2, 3)), rotation,
                                             translation, camera, sigma_px=1.8, peak=240,
                                             blur_sigma_px=0.6, noise_std=2.0, seed=frame)
        stamp = node.get_clock().now().to_msg()
        info.header.stamp = stamp
        info_pub.publish(info)
        msg = array_to_image_msg(image, 'mono8', Image)
        msg.header.stamp, msg.header.frame_id = stamp, 'camera_optical'
        image_pub.publish(msg)
        truths[stamp_to_seconds(stamp)] = (rotation, translation, position)
        frame += 1
        time.sleep(period)
        received, _ = poses.snapshot()
        for pose in received[shown:]:
            key = stamp_to_seconds(pose.header.stamp)
            if key not in truths:
                continue
            true_r, true_t, true_pos = truths[key]
            t = np.array([pose.pose.position.x, pose.pose.position.y, pose.pose.position.z])
            q = pose.pose.orientation
            r = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
            yaw_true, yaw_est = yaw_from_rotation(true_r), yaw_from_rotation(r)
            err = np.degrees(np.angle(np.exp(1j * (yaw_est - yaw_true))))
            rng_true, rng_est = np.linalg.norm(true_t), np.linalg.norm(t)
            cam = -r.T @ t
            ctx.say(f'{key - stamp_to_seconds(received[0].header.stamp):5.1f} '
                    f'{np.degrees(yaw_true) % 360:8.2f}° {np.degrees(yaw_est) % 360:8.2f}° '
                    f'{err:8.3f} {rng_true:10.3f} {rng_est:9.3f} '
                    f'{100 * (rng_est - rng_true) / rng_true:7.3f} '
                    f'  ({cam[0]:6.3f}, {cam[1]:6.3f}, {cam[2]:6.3f}) vs ({true_pos[0]:6.3f}, '
                    f'{true_pos[1]:6.3f}, {true_pos[2]:6.3f})')
        shown = len(received)
    time.sleep(0.5)
    received, _ = poses.snapshot()
    yaw_errors, range_errors = [], []
    for pose in received:
        key = stamp_to_seconds(pose.header.stamp)
        if key in truths:
            q = pose.pose.orientation
            r = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
            t = np.array([pose.pose.position.x, pose.pose.position.y, pose.pose.position.z])
            yaw_errors.append(np.degrees(np.angle(np.exp(
                1j * (yaw_from_rotation(r) - yaw_from_rotation(truths[key][0]))))))
            true_range = np.linalg.norm(truths[key][1])
            range_errors.append(100 * (np.linalg.norm(t) - true_range) / true_range)
    att = attitude.snapshot()[0]
    if att:
        ctx.say(f'attitude in use: roll {np.degrees(att[-1].vector.x):.3f}°, pitch '
                f'{np.degrees(att[-1].vector.y):.3f}° (true {ROLL_DEG}°, {PITCH_DEG}°)')
    ctx.say(f'frames published {frame}, poses {len(received)}, yaw messages '
            f'{len(yaws.snapshot()[0])}; p2p process '
            f'{"running" if proc.proc.poll() is None else "EXITED"}')
    if yaw_errors:
        ctx.say(f'yaw error RMS {np.sqrt(np.mean(np.square(yaw_errors))):.3f}° (max '
                f'{np.max(np.abs(yaw_errors)):.3f}°), range error RMS '
                f'{np.sqrt(np.mean(np.square(range_errors))):.3f} % over {len(yaw_errors)} '
                f'poses, through yaw 180°')
    arrays, _ = diag.snapshot()
    for array in reversed(arrays):
        status = [s for s in array.status if s.name.startswith('p2p')]
        if status:
            values = ', '.join(f'{kv.key}={kv.value}' for kv in status[0].values
                               if kv.key in ('images', 'poses', 'no_pose', 'M1_area_px',
                                             'M2_area_px', 'separation_px'))
            ctx.say(f'/diagnostics: {status[0].name}: {status[0].message} ({values})')
            break
    if not received:
        raise RuntimeError('p2p published no pose (see its log)')
