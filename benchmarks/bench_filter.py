"""
CPU per sample of the attitude filter's core, gyro path, with and without the lever arm.

:class:`~accelcal_ros.sensor.tilt_filter.AttitudeFilter` alone (no ROS) on the simulated
drive (``sensor/drive_sim.py``, seed 0): accelerometer + gyro per sample, the lever arm
unknown (zeros) or the drive's ([1.0, 0.3, 0.8] m: the rotation's acceleration at the
sensor computed and removed per sample, ``sensor/lever_arm.py``). CPU time of this thread
(``time.thread_time``), median of ``--rounds`` passes over the drive, per rate. The node's
cost against the rclpy floor: ``benchmarks/bench_rates.py`` (consumers ``attitude_gyro``,
``attitude_gyro_arm``).

Run: ``python benchmarks/bench_filter.py [--rates 100 800] [--rounds 3]``.
"""
import argparse
import os
import statistics
import time

from accelcal_ros.sensor.datasheet import datasheet_noise_std_g
from accelcal_ros.sensor.drive_sim import simulate_drive
from accelcal_ros.sensor.tilt_filter import AttitudeFilter


def per_sample_us(drive, lever_arm_m, rounds):
    """Return the median CPU microseconds per sample over ``rounds`` passes."""
    t, accel, gyro = drive.t.tolist(), drive.accel_g.tolist(), drive.gyro_rad_s.tolist()
    noise = tuple(datasheet_noise_std_g(drive.rate_hz).tolist())
    out = []
    for _ in range(rounds):
        f = AttitudeFilter(noise_std_g=noise, lever_arm_m=lever_arm_m)
        start = time.thread_time()
        for ti, ai, gi in zip(t, accel, gyro):
            f.update(ti, ai, gi)
        out.append(1e6 * (time.thread_time() - start) / len(t))
    return statistics.median(out)


def main():
    """Print the cost per sample with and without the lever arm."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--rates', type=float, nargs='+', default=[100.0, 800.0])
    parser.add_argument('--rounds', type=int, default=3)
    args = parser.parse_args()
    print(f'attitude filter, gyro path, simulated drive; load {os.getloadavg()[0]:.1f}')
    print(f'{"rate Hz":>8} {"no lever arm us":>16} {"lever arm us":>13} {"ratio":>6}')
    for rate in args.rates:
        drive = simulate_drive(rate, 0)
        base = per_sample_us(drive, None, args.rounds)
        arm = per_sample_us(drive, drive.lever_arm_m, args.rounds)
        print(f'{rate:8g} {base:16.1f} {arm:13.1f} {arm / base:6.2f}', flush=True)


if __name__ == '__main__':
    main()
