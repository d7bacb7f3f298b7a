"""
QoS of the high-rate IMU subscriptions (``imu/data_raw`` at up to 3200 Hz).

rclpy's ``qos_profile_sensor_data`` keeps 5 samples: the driver publishes the ADXL345
FIFO in bursts of up to 32 samples, and a Python consumer that is not scheduled for a
few milliseconds loses whatever does not fit (at 3200 Hz a bare pass-through node got
87 % of the samples with depth 5 and 99 % with depth 500 on a loaded 2-core machine,
``benchmarks/bench_rates.py``). Best effort, so it matches every publisher; deep enough
for 0.3 s at the top rate.
"""
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

IMU_QUEUE_DEPTH = 1000
"""Samples kept by an IMU subscription: 0.31 s at 3200 Hz, about 30 FIFO bursts."""


def imu_subscription_qos(depth: int = IMU_QUEUE_DEPTH) -> QoSProfile:
    """Return best-effort, volatile, keep-last ``depth`` QoS for ``imu/data_raw``."""
    return QoSProfile(depth=depth, history=HistoryPolicy.KEEP_LAST,
                      reliability=ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.VOLATILE)
