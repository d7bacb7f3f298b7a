"""
The floor of a Python IMU consumer: a bare rclpy node that republishes what ``attitude`` does.

Subscribes ``imu/data_raw`` (sensor_msgs/Imu, the QoS ``attitude`` uses) and publishes, for every
sample, ``attitude`` (geometry_msgs/Vector3Stamped) and ``imu/data`` (sensor_msgs/Imu)
with the input's header and no math: the executor and message handling alone. Spun with
rclpy's default executor (``rclpy.spin``). ``benchmarks/bench_rates.py`` compares the CPU
per sample of ``attitude`` and ``calibration`` with this one. Run alone::

    python benchmarks/passthrough_node.py
"""
from accelcal_ros.rosutil.qos import imu_subscription_qos
from geometry_msgs.msg import Vector3Stamped
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import Imu


class PassThroughNode(Node):
    """Republish each sample's header on the two outputs of ``attitude``."""

    def __init__(self, name: str = 'passthrough') -> None:
        super().__init__(name)
        self.attitude_pub = self.create_publisher(Vector3Stamped, 'attitude',
                                                  qos_profile_sensor_data)
        self.imu_pub = self.create_publisher(Imu, 'imu/data', qos_profile_sensor_data)
        self.create_subscription(Imu, 'imu/data_raw', self._on_imu, imu_subscription_qos())
        self._attitude = Vector3Stamped()
        self._imu = Imu()

    def _on_imu(self, msg: Imu) -> None:
        self._attitude.header = msg.header
        self.attitude_pub.publish(self._attitude)
        self._imu.header = msg.header
        self._imu.linear_acceleration = msg.linear_acceleration
        self.imu_pub.publish(self._imu)


def main(args=None) -> int:
    """Spin the pass-through node on rclpy's default executor until Ctrl-C."""
    rclpy.init(args=args)
    node = PassThroughNode()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
