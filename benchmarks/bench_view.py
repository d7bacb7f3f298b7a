"""
Benchmark of the levelled views (issue 24): a view frame against one cv2.remap; views at 25 Hz.

5 cameras of 640x480 (the horizon study's rig at half size), views of 1280x720 with a
60 deg horizontal field of view. First, one view frame against its floor, one bare
``cv2.remap`` of a 1280x720 float map from the same mosaic: with the view still (the
lookup reused, fixed-point maps), moving every frame and with the attitude changing every
frame (each a lookup rebuild by the panorama's fast builder). Then how many 1280x720
views (rendered and JPEG-encoded, as ``accelcal serve`` sends them) fit in a 25 Hz frame
(40 ms) beside the ``stitcher``'s own work on the same frame set (the panorama of the
rig's resolution), one after the other on this machine, still and moving.
Run: ``python benchmarks/bench_view.py [--frames 40] [--threads 2]``.
"""
import argparse
import math
import statistics
import time

from accelcal_ros.panorama.horizon_study import REFERENCE_PITCH_RAD, study_rig
from accelcal_ros.panorama.params import panorama_size
from accelcal_ros.panorama.projection import PanoramaGeometry
from accelcal_ros.panorama.stitch import Stitcher
from accelcal_ros.panorama.view import LevelledView, ViewMosaic, ViewPose
import cv2
import numpy as np


def median_ms(times):
    """Return the median of ``times`` in milliseconds."""
    return 1e3 * statistics.median(times)


def time_frames(frames, step):
    """Run ``step(k)`` ``frames`` times (after 3 warm-up calls); return the durations (s)."""
    for k in range(3):
        step(k)
    times = []
    for k in range(frames):
        start = time.perf_counter()
        step(k + 3)
        times.append(time.perf_counter() - start)
    return times


def main():
    """Run the benchmark and print the figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--frames', type=int, default=40, help='frames per measurement (40)')
    parser.add_argument('--threads', type=int, default=2, help='cv2.setNumThreads (2)')
    parser.add_argument('--width', type=int, default=1280, help='view width (1280)')
    parser.add_argument('--height', type=int, default=720, help='view height (720)')
    args = parser.parse_args()
    cv2.setNumThreads(args.threads)
    rig = study_rig(640, 480)
    rng = np.random.default_rng(0)
    images = [rng.integers(0, 256, (c.height, c.width, 3), dtype=np.uint8)
              for c in rig.cameras]
    mosaic = ViewMosaic(rig)
    for i, image in enumerate(images):
        mosaic.set_image(i, image)
    pitch = REFERENCE_PITCH_RAD
    w, h = args.width, args.height
    print(f'view benchmark: {len(rig)} cameras 640x480, views {w}x{h} of fov_h 60 deg, '
          f'cv2 {cv2.__version__}, {args.threads} OpenCV threads, {args.frames} frames per row')
    view = LevelledView(rig, mosaic.layout, w, h, ViewPose.from_degrees(0, 0, 60))
    view.set_attitude(0.0, pitch)
    float_map = np.ascontiguousarray(view.lookup())
    fixed = cv2.convertMaps(float_map, None, cv2.CV_16SC2)
    out = np.empty((h, w, 3), np.uint8)
    floor = time_frames(args.frames, lambda k: cv2.remap(
        mosaic.image, float_map, None, cv2.INTER_LINEAR, dst=out))
    floor_fixed = time_frames(args.frames, lambda k: cv2.remap(
        mosaic.image, fixed[0], fixed[1], cv2.INTER_LINEAR, dst=out))
    base = median_ms(floor)

    def still(k):
        view.render(mosaic.image)

    def moving(k):
        view.set_pose(ViewPose.from_degrees(-30.0 + 0.7 * (k % 80), 2.0 * math.sin(k / 7),
                                            60.0))
        view.render(mosaic.image)

    def tilting(k):
        view.set_attitude(0.03 * math.sin(k / 5), pitch + 0.02 * math.cos(k / 6))
        view.render(mosaic.image)

    rows = [('cv2.remap, float map (the floor)', floor),
            ('cv2.remap, fixed-point map', floor_fixed),
            ('view, still (lookup reused)', time_frames(args.frames, still))]
    view.set_attitude(0.0, pitch)
    rows.append(('view moving every frame', time_frames(args.frames, moving)))
    rows.append(('attitude changing every frame', time_frames(args.frames, tilting)))
    print(f'\n  {"one view frame " + str(w) + "x" + str(h):34} | median ms | x floor')
    for name, times in rows:
        print(f'  {name:34} | {median_ms(times):9.2f} | {median_ms(times) / base:6.2f}')
    stats = view.builder.last_stats
    print(f'  (rebuild: grid {1e3 * stats.get("grid_s", 0):.2f} ms, cells '
          f'{1e3 * stats.get("cells_s", 0):.2f} ms, resize wait '
          f'{1e3 * stats.get("resize_wait_s", 0):.2f} ms, {stats.get("exact_pixels", 0)} '
          f'pixels exact, step {stats.get("step")})')

    # views beside the stitcher, 25 Hz = 40 ms per frame set
    width, height, _ = panorama_size(rig, 0, 0, 180.0, 120.0)
    stitcher = Stitcher(rig, PanoramaGeometry(width, height, 180.0, 120.0))
    stitcher.set_attitude(0.0, pitch)
    views = [LevelledView(rig, mosaic.layout, w, h, ViewPose.from_degrees(-60 + 30 * i, 0,
                                                                          60))
             for i in range(8)]
    for v in views:
        v.set_attitude(0.0, pitch)

    def frame(count, move):
        def step(k):
            stitcher.update(0.0, pitch, images)
            stitcher.render()
            for i, image in enumerate(images):
                mosaic.set_image(i, image)
            for i, v in enumerate(views[:count]):
                if move:
                    v.set_pose(ViewPose.from_degrees(-60 + 30 * i + 0.5 * (k % 20), 0, 60))
                cv2.imencode('.jpg', v.render(mosaic.image), [cv2.IMWRITE_JPEG_QUALITY, 80])
        return step

    print(f'\n  stitcher {width}x{height} + N views {w}x{h} with JPEG, per frame set '
          '(one thread; 25 Hz = 40 ms)')
    print('  N views | still: ms  | moving: ms')
    fits = {}
    for count in (0, 1, 2, 4, 8):
        t_still = median_ms(time_frames(args.frames // 2, frame(count, False)))
        t_move = median_ms(time_frames(args.frames // 2, frame(count, True)))
        fits[count] = (t_still, t_move)
        print(f'  {count:7d} | {t_still:10.1f} | {t_move:10.1f}')
    zero = fits[0]
    per_still = (fits[8][0] - zero[0]) / 8
    per_move = (fits[8][1] - zero[1]) / 8
    print(f'  each view adds {per_still:.1f} ms still, {per_move:.1f} ms moving: about '
          f'{max(0, int((40 - zero[0]) // per_still))} still or '
          f'{max(0, int((40 - zero[1]) // per_move))} moving views at 25 Hz beside the '
          'stitcher')


if __name__ == '__main__':
    main()
