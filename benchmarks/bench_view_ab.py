"""
A/B of the moving view's per-pose maps: another ``view_grid.py`` against this one, interleaved.

``bench_view.py`` measures its rows in turns, so on a shared machine one row can land on a
slow phase and another on a fast one. Here the floor (one bare 1280x720 ``cv2.remap`` of
the 3-channel mosaic with a fixed-point map) and the two rows "view moving, new frame
set" and "attitude moving, new frame set" (the same steps as ``bench_view.py``) run with
the other file's :class:`GridMaps` and with the installed one, alternating frame by frame
(the order rotated every frame), one OpenCV thread, CPU time of this thread; medians and
ratios to the floor, and the 90th percentile. ``--clock process`` counts the CPU time of
every thread of the process (OpenBLAS's threads, for one, spin on the other core: not
this thread's CPU time; the two files then share one process, so compare each file
against itself in a run of its own), ``--clock wall`` the wall time (what a frame takes
to come, waits on other threads included). The other file is, e.g., ``git show
main~5:accelcal_ros/panorama/view_grid.py > /tmp/old_view_grid.py``.
Run: ``python benchmarks/bench_view_ab.py OTHER_VIEW_GRID.py [--frames 300]
[--clock cpu|process|wall]``.
"""
import argparse
import math
import os
import statistics
import time
import types

from accelcal_ros.panorama import render as scene_render
from accelcal_ros.panorama import view as view_module
from accelcal_ros.panorama import view_grid as this_grid
from accelcal_ros.panorama.horizon_study import REFERENCE_PITCH_RAD, study_rig
from accelcal_ros.panorama.view import LevelledView, ViewMosaic, ViewPose
import cv2
import numpy as np


def main():
    """Print the floor and both rows with the other and this GridMaps."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('other', help='another view_grid.py (the "before")')
    parser.add_argument('--frames', type=int, default=300, help='frames per step (300)')
    parser.add_argument('--clock', choices=('cpu', 'process', 'wall'), default='cpu',
                        help="cpu: this thread's CPU time (default); process: all threads'; "
                        'wall: wall time')
    args = parser.parse_args()
    other = types.ModuleType('other_view_grid')
    with open(args.other, encoding='utf-8') as f:
        exec(compile(f.read(), args.other, 'exec'), other.__dict__)
    cv2.setNumThreads(1)
    rig, pitch, w, h = study_rig(640, 480), REFERENCE_PITCH_RAD, 1280, 720
    scene = scene_render.make_scene(3600, 1800, seed=3)
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(scene_render.render_camera_views(scene, rig, 0.0, pitch)):
        mosaic.set_image(i, image)

    def view():
        v = LevelledView(rig, mosaic.layout, w, h, ViewPose.from_degrees(0, 0, 60))
        v.set_attitude(0.0, pitch)
        return v

    fixed = cv2.convertMaps(np.ascontiguousarray(view().lookup()), None, cv2.CV_16SC2)
    out = np.empty((h, w, 3), np.uint8)

    def moving(module):
        v = view()

        def step(k):
            view_module.GridMaps = module.GridMaps
            v.set_pose(ViewPose.from_degrees(-30.0 + 0.7 * (k % 80), 2.0 * math.sin(k / 7),
                                             60.0))
            v.render(mosaic.image, k)
        return step

    def tilting(module):
        v = view()

        def step(k):
            view_module.GridMaps = module.GridMaps
            v.set_attitude(0.03 * math.sin(k / 5), pitch + 0.02 * math.cos(k / 6))
            v.render(mosaic.image, k)
        return step

    steps = {
        'floor': lambda k: cv2.remap(mosaic.image, fixed[0], fixed[1], cv2.INTER_LINEAR,
                                     dst=out),
        'moving, other': moving(other), 'moving, this': moving(this_grid),
        'attitude, other': tilting(other), 'attitude, this': tilting(this_grid),
    }
    names = list(steps)
    times = {name: [] for name in names}
    clock = {'cpu': time.thread_time, 'process': time.process_time,
             'wall': time.perf_counter}[args.clock]
    for k in range(args.frames + 5):
        for name in names[k % len(names):] + names[:k % len(names)]:
            start = clock()
            steps[name](k)
            if k >= 5:   # warm-up
                times[name].append(clock() - start)
    view_module.GridMaps = this_grid.GridMaps
    floor = statistics.median(times['floor'])
    print(f'cv2 {cv2.__version__}, load {os.getloadavg()[0]:.1f}, {args.frames} frames: '
          f'floor {1e3 * floor:.2f} ms {args.clock}')
    for name in names[1:]:
        ms = statistics.median(times[name])
        p90 = statistics.quantiles(times[name], n=10)[-1]
        print(f'  {name:16} {1e3 * ms:6.2f} ms  x floor {ms / floor:.2f}  '
              f'(90th percentile {1e3 * p90:6.2f} ms, x floor {p90 / floor:.2f})')


if __name__ == '__main__':
    main()
