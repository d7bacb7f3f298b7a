"""
A simulated camera rig as a process: rendered views of a rig at a fixed attitude.

``python -m graph_harness.camera_sim --rig RIG.yaml [--rate 5] [--transport both]``
publishes, for every camera of the rig, ``<name>/image_raw`` (sensor_msgs/Image, bgr8)
and/or ``<name>/image_raw/compressed`` (sensor_msgs/CompressedImage, JPEG, as
image_transport's compressed plugin writes it), reliable keep-last 5, one stamp per set
(as hardware-triggered cameras), until SIGINT/SIGTERM. The views are rendered once
(:func:`accelcal_ros.panorama.render.render_camera_views` of a seeded scene at
``--roll-deg``/``--pitch-deg``). Used by the two-host graph test.
"""
import argparse
import math
import signal
import time


def main(argv=None):
    """Publish the rig's views until stopped."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rig', required=True)
    parser.add_argument('--rate', type=float, default=5.0)
    parser.add_argument('--roll-deg', type=float, default=2.0)
    parser.add_argument('--pitch-deg', type=float, default=10.0)
    parser.add_argument('--transport', choices=('raw', 'compressed', 'both'), default='both')
    parser.add_argument('--quality', type=int, default=90)
    args = parser.parse_args(argv)

    from accelcal_ros.camera.rig import load_rig
    from accelcal_ros.panorama import render
    from accelcal_ros.rosutil.compressed import encode_compressed
    from accelcal_ros.rosutil.images import array_to_image_msg
    import rclpy
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import CompressedImage, Image

    rig = load_rig(args.rig)
    scene = render.make_scene(1800, 900, seed=2)
    views = render.render_camera_views(scene, rig, math.radians(args.roll_deg),
                                       math.radians(args.pitch_deg))
    rclpy.init()
    node = rclpy.create_node('camera_sim')
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
    outputs = []
    for camera, view in zip(rig.cameras, views):
        raw = compressed = None
        if args.transport in ('raw', 'both'):
            raw = (node.create_publisher(Image, f'{camera.name}/image_raw', qos),
                   array_to_image_msg(view, 'bgr8', Image))
        if args.transport in ('compressed', 'both'):
            fmt, data = encode_compressed(view, 'bgr8', 'jpeg', args.quality)
            compressed = (node.create_publisher(CompressedImage,
                                                f'{camera.name}/image_raw/compressed', qos),
                          CompressedImage(format=fmt, data=data))
        for pair in (raw, compressed):
            if pair is not None:
                pair[1].header.frame_id = f'{camera.name}_optical'
                outputs.append(pair)
    stop = []
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.append(True))
    period = 1.0 / args.rate
    next_t = time.monotonic()
    while not stop:
        sec, nanosec = divmod(time.time_ns(), 10 ** 9)
        for pub, msg in outputs:
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nanosec
            pub.publish(msg)
        next_t += period
        time.sleep(max(0.0, next_t - time.monotonic()))
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
