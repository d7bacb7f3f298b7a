"""
Benchmark of the levelled views (issue 24): a view frame against one cv2.remap; views at 25 Hz.

5 cameras of 640x480 (the horizon study's rig at half size, images rendered from the
test scene), views of 1280x720 with a 60 deg horizontal field of view.

Part 1, one view frame against its floor: one bare ``cv2.remap`` of the same 1280x720
output from the same mosaic with a precomputed map. The floor's map is the type a
precomputed map is used in (the still view, the stitcher): 16-bit fixed point
(``CV_16SC2`` + ``CV_16UC1``, from ``cv2.convertMaps``); a float map (``CV_32FC2``, the
earlier floor, slower) is printed beside it. Rows: the view still (its lookup reused),
moving every frame (the frame set unchanged, or a new frame set every frame: live
video), the attitude changing with every new frame set -- these with the default
renderer (``'grid'``: a frame set's first frame straight from the camera images by
interpolated maps, the same set again from the cameras' undistorted planes) --, the
view moving over new frame sets from the planes only (``'warp'``, the previous way),
and with the lookup renderer (``'map'``: a rebuild by the fast builder every frame).
Each figure twice: wall time with ``--threads`` OpenCV threads, and CPU time of the one
thread doing the work
with one OpenCV thread (``time.thread_time``: what the frame costs, little affected by
other processes on a shared machine). Rows are measured in turns, ``--rounds`` times.

Part 2, views beside the ``stitcher`` on the same rig (its panorama at the rig's
resolution, attitude fixed): CPU time per frame set of the stitcher, of copying the frame
set into the views' mosaic, and of N views rendered and JPEG-encoded as ``accelcal
serve`` sends them (q80, :func:`accelcal_ros.jpeg.encode_jpeg`: simplejpeg when
installed), still and moving, N = 1, 2, 4, 6. On a 2-core machine a 25 Hz frame set
has 2 x 40 = 80 CPU ms: N views fit when the total does. Then
the same work run at once, the stitcher in one thread and the views in a pool of two
(as the stitcher's view thread and ``accelcal serve`` do), unpaced, for ``--frames``
frame sets: frame sets per second reached (>= 25: N views at 25 Hz fit on this machine,
now, with whatever else it runs). ``os.getloadavg()`` is printed with each part.
Run: ``python benchmarks/bench_view.py [--frames 30] [--rounds 5] [--threads 2]``.
"""
import argparse
from concurrent.futures import ThreadPoolExecutor
import math
import os
import statistics
import time

from accelcal_ros.jpeg import encode_jpeg, encoder
from accelcal_ros.panorama import render as scene_render
from accelcal_ros.panorama.horizon_study import REFERENCE_PITCH_RAD, study_rig
from accelcal_ros.panorama.params import panorama_size
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.stitch import Stitcher
from accelcal_ros.panorama.view import LevelledView, ViewMosaic, ViewPose
from accelcal_ros.panorama.view_set import ViewSet
import cv2
import numpy as np


def load():
    """Return the 1-minute load average as text."""
    return f'load {os.getloadavg()[0]:.1f}'


def measure(steps, frames, rounds, clock):
    """Run every ``steps[name](k)`` ``frames`` times per round, in turns; return ms lists."""
    out = {name: [] for name in steps}
    k = 0
    for name, step in steps.items():  # warm-up
        for _ in range(3):
            step(k)
            k += 1
    for _ in range(rounds):
        for name, step in steps.items():
            for _ in range(frames):
                start = clock()
                step(k)
                out[name].append(1e3 * (clock() - start))
                k += 1
    return out


def view_rows(rig, images, w, h, pitch):
    """Return the steps of part 1 (name -> step(k))."""
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(images):
        mosaic.set_image(i, image)
    ref = LevelledView(rig, mosaic.layout, w, h, ViewPose.from_degrees(0, 0, 60))
    ref.set_attitude(0.0, pitch)
    float_map = np.ascontiguousarray(ref.lookup())
    fixed = cv2.convertMaps(float_map, None, cv2.CV_16SC2)
    out = np.empty((h, w, 3), np.uint8)

    def view(renderer='grid'):
        v = LevelledView(rig, mosaic.layout, w, h, ViewPose.from_degrees(0, 0, 60),
                         renderer=renderer)
        v.set_attitude(0.0, pitch)
        return v

    still, moving, fresh, tilting = view(), view(), view(), view()
    planes, old = view('warp'), view('map')

    def pose(k):
        return ViewPose.from_degrees(-30.0 + 0.7 * (k % 80), 2.0 * math.sin(k / 7), 60.0)

    def move(v, version):
        def step(k):
            v.set_pose(pose(k))
            v.render(mosaic.image, version(k))
        return step

    def tilt(k):
        tilting.set_attitude(0.03 * math.sin(k / 5), pitch + 0.02 * math.cos(k / 6))
        tilting.render(mosaic.image, k)

    return {
        'cv2.remap, fixed-point map (floor)': lambda k: cv2.remap(
            mosaic.image, fixed[0], fixed[1], cv2.INTER_LINEAR, dst=out),
        'cv2.remap, float map': lambda k: cv2.remap(
            mosaic.image, float_map, None, cv2.INTER_LINEAR, dst=out),
        'view still (lookup reused)': lambda k: still.render(mosaic.image, 0),
        'view moving, same frame set': move(moving, lambda k: 0),
        'view moving, new frame set': move(fresh, lambda k: k),
        'attitude moving, new frame set': tilt,
        'view moving, new frame set, planes': move(planes, lambda k: k),
        'view moving, lookup rebuilt': move(old, lambda k: None),
    }


def part1(args, rig, images, pitch):
    """Print one view frame against the floors."""
    w, h = args.width, args.height
    cv2.setNumThreads(args.threads)
    wall = measure(view_rows(rig, images, w, h, pitch), args.frames, args.rounds,
                   time.perf_counter)
    cv2.setNumThreads(1)
    cpu = measure(view_rows(rig, images, w, h, pitch), args.frames, args.rounds,
                  time.thread_time)
    floors = [n for n in wall if n.startswith('cv2.remap')]
    base_w = [statistics.median(wall[n]) for n in floors]
    base_c = [statistics.median(cpu[n]) for n in floors]
    print(f'\n  one view frame {w}x{h} ({load()}) | wall ms ({args.threads} thr) | x fixed '
          '| x float | CPU ms (1 thr) | x fixed | x float')
    for name in wall:
        mw, mc = statistics.median(wall[name]), statistics.median(cpu[name])
        print(f'  {name:35} | {mw:18.2f} | {mw / base_w[0]:7.2f} | {mw / base_w[1]:7.2f} | '
              f'{mc:14.2f} | {mc / base_c[0]:7.2f} | {mc / base_c[1]:7.2f}')


def part2(args, rig, images, pitch):
    """Print the views that fit beside the stitcher at 25 Hz."""
    cv2.setNumThreads(1)
    width, height, _ = panorama_size(rig, 0, 0, 180.0, 120.0)
    stitcher = Stitcher(rig, PanoramaGeometry(width, height, 180.0, 120.0))
    stitcher.set_attitude(0.0, pitch)
    frame_sets = [[np.roll(image, 3 * k, axis=1) for image in images] for k in range(4)]
    counts = (0, 1, 2, 4, 6)

    def views_for(count):
        views = ViewSet(rig, max_views=8, width=args.width, height=args.height)
        for i in range(count):
            views.add(f'v{i}', ViewPose.from_degrees(-60 + 24 * i, 0, 60))
        views.set_frame(frame_sets[0], 0.0, pitch)
        return views

    def view_job(views, name, move, k):
        if move:
            i = int(name[1:])
            views.set_pose(name, ViewPose.from_degrees(-60 + 24 * i + 0.5 * (k % 20), 0, 60))
        with views.drawing(name) as (_, image):
            pass
        encode_jpeg(image, 80)   # as accelcal serve: outside the drawing

    def stitch_job(k):
        stitcher.update(0.0, pitch, frame_sets[k % 4])
        stitcher.render()

    # CPU time per frame set, one piece after the other in this thread
    cpu = {}
    stitch_ms = statistics.median(measure({'s': stitch_job}, args.frames, 1,
                                          time.thread_time)['s'])
    views = views_for(6)
    copy_ms = statistics.median(measure(
        {'c': lambda k: views.set_frame(frame_sets[k % 4], 0.0, pitch)}, args.frames, 1,
        time.thread_time)['c'])
    for move in (False, True):
        def all_views(k, move=move):
            views.set_frame(frame_sets[k % 4], 0.0, pitch)
            for name in views.names():
                view_job(views, name, move, k)
        per_set = statistics.median(measure({'v': all_views}, args.frames, 1,
                                            time.thread_time)['v'])
        cpu[move] = (per_set - copy_ms) / 6
    print(f'\n  beside the stitcher {width}x{height} ({load()}), CPU ms per frame set '
          f'(1 OpenCV thread): stitcher {stitch_ms:.1f}, frame set into the views mosaic '
          f'{copy_ms:.1f}, one {args.width}x{args.height} view + JPEG q80 ({encoder()}): still '
          f'{cpu[False]:.1f}, moving {cpu[True]:.1f}')
    print('  N views | CPU ms/frame set still | moving | of 80 (2 cores x 40 ms) | '
          'run at once: frame sets/s still | moving')
    pool = ThreadPoolExecutor(max_workers=2)
    side = ThreadPoolExecutor(max_workers=1)
    for count in counts:
        need = [stitch_ms + (copy_ms + count * cpu[m] if count else 0.0) for m in (False, True)]
        rates = []
        for move in (False, True):
            views = views_for(count)
            names = views.names()
            start = time.perf_counter()
            for k in range(args.frames):
                stitched = side.submit(stitch_job, k)
                if names:
                    views.set_frame(frame_sets[k % 4], 0.0, pitch)
                    list(pool.map(lambda n, k=k: view_job(views, n, move, k), names))
                stitched.result()
            rates.append(args.frames / (time.perf_counter() - start))
        print(f'  {count:7d} | {need[0]:22.1f} | {need[1]:6.1f} | '
              f'{"fits" if need[1] <= 80 else "over":>4} {need[1] / 80:4.0%} (moving) | '
              f'{rates[0]:30.1f} | {rates[1]:6.1f}   ({load()})')
    pool.shutdown()
    side.shutdown()
    fit = [int((80 - stitch_ms - copy_ms) // cpu[m]) for m in (False, True)]
    print(f'  by CPU time: {fit[0]} still or {fit[1]} moving {args.width}x{args.height} views '
          f'with JPEG at 25 Hz beside the stitcher on 2 cores ((80 - {stitch_ms:.1f} - '
          f'{copy_ms:.1f}) / per view; the count scales with 1 / per-view cost and with '
          'the cores)')


def main():
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--frames', type=int, default=30, help='frames per measurement (30)')
    parser.add_argument('--rounds', type=int, default=5, help='turns over the rows (5)')
    parser.add_argument('--threads', type=int, default=2, help='OpenCV threads, wall (2)')
    parser.add_argument('--width', type=int, default=1280, help='view width (1280)')
    parser.add_argument('--height', type=int, default=720, help='view height (720)')
    parser.add_argument('--skip-views-per-machine', action='store_true',
                        help='part 1 only')
    args = parser.parse_args()
    rig = study_rig(640, 480)
    pitch = REFERENCE_PITCH_RAD
    scene = scene_render.make_scene(3600, 1800, seed=3)
    images = scene_render.render_camera_views(scene, rig, 0.0, pitch)
    print(f'view benchmark: {len(rig)} cameras 640x480, views {args.width}x{args.height} of '
          f'fov_h 60 deg, cv2 {cv2.__version__}, {os.cpu_count()} CPUs, {load()}')
    part1(args, rig, images, pitch)
    if not args.skip_views_per_machine:
        part2(args, rig, images, pitch)


if __name__ == '__main__':
    main()
