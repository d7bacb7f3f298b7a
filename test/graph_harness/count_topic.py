"""
Count the messages of one topic for a while (a probe process for other hosts).

``python -m graph_harness.count_topic imu/data_raw sensor_msgs/msg/Imu --count 50
--timeout 20`` prints one JSON line: ``{"count": N, "seconds": S}`` once ``--count``
messages arrived or the timeout passed (sensor-data QoS).
"""
import argparse
import importlib
import json
import time


def main(argv=None):
    """Subscribe, count, print the JSON line."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('topic')
    parser.add_argument('type', help='e.g. sensor_msgs/msg/Imu')
    parser.add_argument('--count', type=int, default=10)
    parser.add_argument('--timeout', type=float, default=20.0)
    args = parser.parse_args(argv)
    package, _, name = args.type.split('/')
    msg_type = getattr(importlib.import_module(f'{package}.msg'), name)

    import rclpy
    from rclpy.qos import qos_profile_sensor_data

    rclpy.init()
    node = rclpy.create_node('count_topic')
    got = []
    node.create_subscription(msg_type, args.topic, lambda msg: got.append(1),
                             qos_profile_sensor_data)
    start = time.monotonic()
    while len(got) < args.count and time.monotonic() - start < args.timeout:
        rclpy.spin_once(node, timeout_sec=0.1)
    print(json.dumps({'count': len(got), 'seconds': time.monotonic() - start}), flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
