"""Demo stage ``driver``: the ADXL345 driver on the simulated sensor, with a live readout."""
import time

from accelcal_ros.sensor.units import STANDARD_GRAVITY_M_S2 as STANDARD_GRAVITY
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Vector3Stamped
import numpy as np
from sensor_msgs.msg import Imu


def run(ctx):
    """Start ``imu_driver`` (sim, 200 Hz) and print what it publishes for a few seconds."""
    rate = 200.0
    imu = ctx.graph.collect(Imu, 'imu/data_raw')
    truth = ctx.graph.collect(Vector3Stamped, 'sim/attitude_truth')
    diag = ctx.graph.collect(DiagnosticArray, '/diagnostics', 10)
    ctx.say('$ ros2 run accelcal_ros imu_driver --ros-args -p backend:=sim -p rate_hz:=200.0 '
            '-p sim.dwell_s:=1.5 -p sim.move_s:=0.5')
    ctx.graph.start('imu_driver', {'backend': 'sim', 'rate_hz': rate, 'sim.dwell_s': 1.5,
                                   'sim.move_s': 0.5})
    imu.wait_for(1, timeout=30.0)
    ctx.say('$ ros2 topic echo imu/data_raw   (one line per 0.5 s; m/s^2, REP-145: +g up)')
    ctx.say(f'{"t s":>5} {"ax":>7} {"ay":>7} {"az":>7} {"|a| g":>6} {"true roll":>9} '
            f'{"true pitch":>10} {"rate Hz":>8} {"latency ms":>10}')
    start = time.monotonic()
    duration = 3.0 if ctx.quick else 6.0
    imu.clear()
    while time.monotonic() - start < duration:
        time.sleep(0.5)
        msgs, received = imu.snapshot()
        truths, _ = truth.snapshot()
        if not msgs or not truths:
            continue
        m = msgs[-1]
        a = m.linear_acceleration
        stamps = np.array([x.header.stamp.sec + x.header.stamp.nanosec * 1e-9 for x in msgs])
        recent = stamps > stamps[-1] - 0.5
        latency = np.median(np.array(received)[recent] - stamps[recent]) * 1e3
        t = truths[-1].vector
        ctx.say(f'{time.monotonic() - start:5.1f} {a.x:7.3f} {a.y:7.3f} {a.z:7.3f} '
                f'{np.linalg.norm([a.x, a.y, a.z]) / STANDARD_GRAVITY:6.3f} '
                f'{np.degrees(t.x):8.1f}° {np.degrees(t.y):9.1f}° '
                f'{recent.sum() / 0.5:8.0f} {latency:10.2f}')
    m = imu.snapshot()[0][-1]
    variances = np.reshape(m.linear_acceleration_covariance, (3, 3)).diagonal()
    ctx.say(f'frame_id={m.header.frame_id} orientation_covariance[0]='
            f'{m.orientation_covariance[0]:g} (not provided) linear_acceleration_covariance='
            f'diag({", ".join(f"{v:.2e}" for v in variances)}) (m/s^2)^2')
    arrays, _ = diag.snapshot()
    for array in arrays[-1:]:
        for status in array.status:
            values = ', '.join(f'{kv.key}={kv.value}' for kv in status.values if kv.value)
            ctx.say(f'/diagnostics: {status.name}: {status.message} ({values})')
