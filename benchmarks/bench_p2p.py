"""
Benchmark of the P2P feature: solves per second (single and batch), detection per image.

    python benchmarks/bench_p2p.py [--quick]

Prints the figures quoted in docs/p2p.md. Problems are the study's random scenes
(noise-free); detection runs on rendered 1280 x 960 mono8 frames (two Gaussian emitters,
blur, noise; plumb_bob distortion for the undistortion step).
"""
import argparse
import time

from accelcal_ros.camera import CameraModel
from accelcal_ros.p2p import beacons, render, solver, study
import numpy as np


def best_of(function, repeats):
    """Return the fastest wall time (s) of ``repeats`` calls of ``function``."""
    best = float('inf')
    for _ in range(repeats):
        start = time.perf_counter()
        function()
        best = min(best, time.perf_counter() - start)
    return best


def main():
    """Run the benchmark and print its figures."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true', help='fewer repetitions')
    args = parser.parse_args()
    repeats = 3 if args.quick else 7
    rng = np.random.default_rng(0)
    scenes = study.random_scenes(100000, rng)
    down = scenes.rotations @ np.array([0.0, 0.0, -1.0])

    single_n = 2000 if args.quick else 10000

    def singles():
        for k in range(single_n):
            solver.solve(scenes.rays[k], scenes.points[k], down[k])

    single_s = best_of(singles, repeats)
    one_batch_s = best_of(lambda: solver.solve_batch(scenes.rays[:1], scenes.points[:1],
                                                     down[:1]), repeats * 50)
    batch_s = best_of(lambda: solver.solve_batch(scenes.rays, scenes.points, down), repeats)
    result = solver.solve_batch(scenes.rays, scenes.points, down)
    error = np.abs(result.translations[:, 0] - scenes.translations).max()
    print(f'solver, single (solver.solve): {single_n / single_s:12.0f} solves/s '
          f'({single_s / single_n * 1e6:.1f} us each)')
    print(f'solver, batch of 1:            {1 / one_batch_s:12.0f} solves/s')
    print(f'solver, batch of 100000:       {len(scenes.rays) / batch_s:12.0f} solves/s '
          f'({len(scenes.rays) / batch_s * single_s / single_n:.0f}x single); max |t error| '
          f'{error:.1e} m at range 1 m')

    camera = CameraModel.from_fov(1280, 960, 60.0,
                                  dist_coeffs=[-0.12, 0.03, 0.0, 0.0, 0.0])
    points = np.array([[0.0, -0.25, 0.0], [0.0, 0.25, 0.0]])
    rotation, translation = render.pose_from_camera_attitude(
        np.radians(3.0), np.radians(15.0), np.pi, [4.0, 0.0, 1.07])
    image, _, _ = render.render_emitters(points, rotation, translation, camera, sigma_px=1.8,
                                         blur_sigma_px=0.6, noise_std=2.0)
    settings = beacons.DetectorSettings(threshold=60)
    up = rotation @ np.array([0.0, 0.0, -1.0])
    detect_s = best_of(lambda: beacons.detect_beacons(image, settings), repeats * 10)
    full_s = best_of(lambda: solver.solve(beacons.detect_beacons(
        image, settings, camera, down=up).rays, points, up),
        repeats * 10)
    # the same frame with the batch solver for one problem (were it the only solver)
    full_batch_s = best_of(lambda: solver.solve_batch(beacons.detect_beacons(
        image, settings, camera, down=up).rays[None], points, up).solutions(0),
        repeats * 10)
    corners = render.draw_spots((960, 1280), [[20.0, 20.0], [1260.0, 940.0]], 1.8, 240.0)
    corners = np.clip(corners + rng.standard_normal(corners.shape) * 2.0, 0, 255)
    corners = corners.astype(np.uint8)
    worst_s = best_of(lambda: beacons.detect_beacons(corners, settings), repeats * 10)
    print(f'detection, 1280x960 mono8:     {detect_s * 1e3:12.2f} ms per image '
          f'(threshold, components, centroids)')
    print(f'detection, emitters in opposite corners: {worst_s * 1e3:6.2f} ms per image '
          f'(labelling the whole frame)')
    print(f'frame, detect+undistort+solve: {full_s * 1e3:12.2f} ms per image '
          f'({1 / full_s:.0f} frames/s on one core)')
    print(f'frame, the same with solve_batch: {full_batch_s * 1e3:9.2f} ms per image '
          f'({full_batch_s / full_s:.2f}x: why solve() keeps its scalar form)')


if __name__ == '__main__':
    main()
