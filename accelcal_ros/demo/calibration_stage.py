"""
Demo stage ``calibration``: field calibration and attitude on the simulated ADXL345.

Starts ``imu_driver`` (sim: paper A's K=500 sensor visiting 14 orientations),
``calibration`` and ``attitude`` as processes, calls ``calibration/start``, shows the
progress the node publishes (captures, sphere coverage, predicted roll/pitch error, hint),
calls ``calibration/finish``, prints the fitted scale and bias against the simulator's
truth and the attitude error against ``sim/attitude_truth`` in still dwells, before and
after the calibration was applied. Writes ``calibration.yaml`` and ``calibration.png``.
"""
import os
import time

from accelcal_ros.calibration.coverage import recommended_directions, roll_pitch_deg_of
from accelcal_ros.driver.sim_truth import dwell_errors_deg
from accelcal_ros.sensor.calibration_file import load_calibration
from accelcal_ros.sensor.model import paper_a_model
import numpy as np


def _values(msg):
    return {kv.key: kv.value for kv in msg.values}


def _say_errors(ctx, label, errors):
    if not errors:
        ctx.say(f'{label}: no complete still dwell seen')
        return
    worst = max(float(np.abs(v).max()) for v in errors.values())
    ctx.say(f'{label}: {len(errors)} still dwells, worst mean roll/pitch error {worst:.3f} deg')
    for (roll, pitch), err in sorted(errors.items()):
        ctx.say(f'    true roll {roll:7.1f} pitch {pitch:6.1f} deg -> error roll '
                f'{err[0]:+7.3f} pitch {err[1]:+7.3f} deg')


def run(ctx):
    """Run the calibration flow in a live graph and print the readout."""
    from diagnostic_msgs.msg import DiagnosticStatus
    from geometry_msgs.msg import Vector3Stamped
    from std_srvs.srv import Trigger

    dwell, move, still = (1.0, 0.4, 0.7) if ctx.quick else (1.5, 0.6, 1.0)
    truth = paper_a_model(500)
    poses = roll_pitch_deg_of(recommended_directions(14)).ravel().tolist()
    output = os.path.abspath(os.path.join(ctx.out_dir, 'calibration.yaml'))
    ctx.say(f'$ ros2 run accelcal_ros imu_driver --ros-args -p backend:=sim -p rate_hz:=100.0 '
            f'-p sim.dwell_s:={dwell} -p sim.move_s:={move} -p "sim.poses_deg:=[14 '
            'orientations: 6 box faces + 8 corners]"   (truth: paper A K=500 sensor)')
    ctx.graph.start('imu_driver', {'backend': 'sim', 'rate_hz': 100.0, 'seed': 7,
                                   'sim.poses_deg': poses, 'sim.dwell_s': dwell,
                                   'sim.move_s': move})
    ctx.say(f'$ ros2 run accelcal_ros calibration --ros-args -p output_file:={output} '
            f'-p min_still_s:={still}')
    ctx.graph.start('calibration', {'output_file': output, 'min_still_s': still})
    ctx.say('$ ros2 run accelcal_ros attitude')
    ctx.graph.start('attitude')
    status = ctx.graph.collect(DiagnosticStatus, 'calibration/status', 10)
    attitude = ctx.graph.collect(Vector3Stamped, 'attitude')
    truth_topic = ctx.graph.collect(Vector3Stamped, 'sim/attitude_truth')

    ctx.say('$ ros2 service call /calibration/start std_srvs/srv/Trigger')
    reply = ctx.graph.call(Trigger, 'calibration/start', timeout=30.0)
    ctx.say(f'  -> success={reply.success}: {reply.message}')
    ctx.say('$ ros2 topic echo /calibration/status   (one line per change)')
    deadline = time.monotonic() + (40.0 if ctx.quick else 60.0)
    shown, positions = None, 0
    while time.monotonic() < deadline and positions < 14:
        time.sleep(0.25)
        messages, _ = status.snapshot()
        if not messages:
            continue
        v = _values(messages[-1])
        positions = int(v.get('captures', 0))
        line = (f'  positions {positions:2d} (need {v.get("captures_needed")})  coverage '
                f'{v.get("coverage_percent"):>3} %  predicted roll/pitch p95 '
                f'{(v.get("predicted_error_deg") or "n/a"):>6} deg')
        if v.get('hint'):
            line += f'  add: {v["hint"].split(";")[0]}'
        if line != shown:
            ctx.say(line)
            shown = line
    before = dwell_errors_deg(attitude.snapshot()[0], truth_topic.snapshot()[0])

    ctx.say('$ ros2 service call /calibration/finish std_srvs/srv/Trigger')
    reply = ctx.graph.call(Trigger, 'calibration/finish', timeout=30.0)
    ctx.say(f'  -> success={reply.success}: {reply.message}')
    if not reply.success:
        raise RuntimeError(f'calibration/finish failed: {reply.message}')
    record = load_calibration(output)
    fitted = record.sensor_model
    ctx.say(f'{"":13}{"x":>10}{"y":>10}{"z":>10}')
    for name, est, std, true in (('scale', fitted.scale, record.scale_std, truth.scale),
                                 ('bias (g)', fitted.bias, record.bias_std, truth.bias)):
        ctx.say(f'{name + " fitted":13}' + ''.join(f'{x:10.5f}' for x in est))
        ctx.say(f'{"  +- 1 std":13}' + ''.join(f'{x:10.5f}' for x in std))
        ctx.say(f'{"  truth":13}' + ''.join(f'{x:10.5f}' for x in true))
    ctx.say(f'misalignment fitted {np.round(fitted.misalignment * 1e3, 3).tolist()} mrad '
            '(truth 0)')
    _say_errors(ctx, 'attitude BEFORE the calibration (uncalibrated)', before)

    time.sleep(0.5)  # the parameter update reaches the attitude node
    attitude.clear()
    truth_topic.clear()
    time.sleep(4.0 if ctx.quick else 8.0)
    after = dwell_errors_deg(attitude.snapshot()[0], truth_topic.snapshot()[0])
    _say_errors(ctx, 'attitude AFTER calibration/finish applied it (no restart)', after)
    ctx.say(f'predicted roll/pitch error p95 from the fit: '
            f'{record.predicted_tilt_error_deg:.3f} deg (target < 0.1 deg; paper A: 1.5-3 deg '
            'at K=100-300)')
    try:
        from accelcal_ros.calibration.plot import plot_calibration_file

        png = os.path.join(ctx.out_dir, 'calibration.png')
        plot_calibration_file(png, output)
        ctx.say(f'wrote {output} and {png}')
    except ImportError:
        ctx.say(f'wrote {output} (matplotlib missing: no plot)')
