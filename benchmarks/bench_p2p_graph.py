"""
Benchmark of the ``p2p`` node in a real ROS graph (issue 16): poses per second.

One run: a publisher process sends one 1280x960 mono8 camera at 30 Hz (reliable, with
its camera_info, rendered emitters at a known pose) plus the attitude at 100 Hz; the
floor is a bare rclpy subscriber process to ``image`` (deserialising, and raw); then the
``p2p`` node with its defaults (``emitters`` and ``threshold`` set for the scene) and a
subscriber process of ``pose``: poses per second and the latency (image stamp to pose
receipt). Target (issue 16): at least 0.95x the floor's images per second. The
processes are those of ``bench_panorama_graph.py``. Short runs are indicative only.
Run: ``python benchmarks/bench_p2p_graph.py [--duration 10] [--rate 30]``.
"""
import argparse
import json
import math
import os
import sys
import tempfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import bench_panorama_graph as graph_bench  # noqa: E402,I100 - the sibling script

EMITTERS = [-0.4, 0.0, 0.0, 0.4, 0.0, 0.0]


def scene(width, height):
    """Return the rendered image, K (9 values), roll and pitch (deg) of the test scene."""
    from accelcal_ros.camera import CameraModel
    from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA, rpy_radians_from_rotation
    from accelcal_ros.p2p import render

    camera = CameraModel.from_fov(width, height, 60.0)
    yaw = math.radians(150.0)
    rotation, translation = render.pose_from_camera_attitude(
        math.radians(4.0), math.radians(20.0), yaw,
        [-3.0 * math.cos(yaw), -3.0 * math.sin(yaw), 1.1])
    image, _, _ = render.render_emitters(np.reshape(EMITTERS, (2, 3)), rotation, translation,
                                         camera, noise_std=1.5)
    roll, pitch, _ = rpy_radians_from_rotation(rotation.T @ DEFAULT_IMU_TO_CAMERA)
    k = [float(v) for v in np.asarray(camera.camera_matrix).reshape(-1)]
    return image, k, math.degrees(roll), math.degrees(pitch)


def main():
    """Run the benchmark and print the figures."""
    from graph_harness.graph import NodeProcess

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--duration', type=float, default=10.0, help='seconds measured')
    parser.add_argument('--warmup', type=float, default=3.0, help='seconds not counted')
    parser.add_argument('--rate', type=float, default=30.0, help='camera rate (Hz)')
    parser.add_argument('--width', type=int, default=1280)
    parser.add_argument('--height', type=int, default=960)
    args = parser.parse_args()
    holder = graph_bench.isolated_domain()
    print(f'p2p in a ROS graph, {args.duration:g} s per phase (ROS_DOMAIN_ID '
          f'{os.environ.get("ROS_DOMAIN_ID", "0")}); indicative on a loaded machine')
    with tempfile.TemporaryDirectory() as workdir:
        image, k, roll_deg, pitch_deg = scene(args.width, args.height)
        npy = os.path.join(workdir, 'image.npy')
        np.save(npy, image.astype(np.uint8))
        info = json.dumps({'width': args.width, 'height': args.height, 'K': k})
        common = ['--topics', 'image', '--duration', args.duration, '--warmup', args.warmup]

        def bare_phase(raw):
            return lambda: ([], graph_bench.child('bare', *common,
                                                  *(['--raw'] if raw else [])))

        def node_phase():
            node = NodeProcess('p2p', {'emitters': EMITTERS, 'threshold': 60},
                               log_dir=workdir)
            return [node], graph_bench.child(
                'sink', '--topic', 'pose', '--msg-type', 'pose', '--diag-prefix', 'p2p',
                '--sub-depth', 10, '--duration', args.duration, '--warmup', args.warmup)

        options = ['--topics', 'image', '--width', args.width, '--height', args.height,
                   '--rate', args.rate, '--encoding', 'mono8', '--image-npy', npy,
                   '--camera-info', info, '--roll-deg', roll_deg, '--pitch-deg', pitch_deg]
        results = graph_bench.run_graph(options, [
            ('floor (deserialised)', bare_phase(False)), ('floor (raw)', bare_phase(True)),
            ('p2p', node_phase)], args.duration, args.warmup)
        graph_bench.report(f'1x{args.width}x{args.height}@{args.rate:g} mono8', results,
                           ratio=0.95, what='poses', duration_s=args.duration)
    del holder
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
