"""
Benchmark of the LiDAR feature (paper B): plane fit, Open3D agreement, georeferencing, boresight.

Run:  source tools/env.sh && python benchmarks/bench_lidar.py [--quick]
With Open3D (kept out of the project venv, it pins its own numpy):
  python3 -m venv /tmp/o3d && /tmp/o3d/bin/pip install open3d pyyaml scipy
  PYTHONPATH=$PWD /tmp/o3d/bin/python benchmarks/bench_lidar.py
(Open3D needs libusb-1.0 at import: ``apt-get install libusb-1.0-0`` on a bare machine.)
"""
import argparse
import os
import tempfile
import time

from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.boresight import calibrate_boresight
from accelcal_ros.lidar.cloud import point_times, xyz
from accelcal_ros.lidar.georef import georeference
from accelcal_ros.lidar.pcd import read_pcd, write_pcd
from accelcal_ros.lidar.plane_fit import find_floor, FloorSearch, prepare_floor_candidates
from accelcal_ros.lidar.poses import PoseStream
from accelcal_ros.lidar.wahba import rotation_angle_deg
import numpy as np
from scipy.spatial.transform import Rotation


def _angle(n1, n2):
    c = abs(float(np.dot(n1, n2)) / np.linalg.norm(n1) / np.linalg.norm(n2))
    return float(np.degrees(np.arccos(min(1.0, c))))


def bench_plane_fit(protocol, repeats):
    """Time our floor search and Open3D's segment_plane on the same cropped clouds."""
    try:
        import open3d as o3d
    except ImportError:
        o3d = None
    search = FloorSearch()
    prior = sim.nominal_mount()
    rows = []
    for pos in protocol:
        pts = xyz(pos.cloud)
        up_true = pos.rotation_world_lidar.T @ [0.0, 0.0, 1.0]
        up = prior.T @ (pos.imu.accel[-500:].mean(axis=0))
        cand, _ = prepare_floor_candidates(pts, search, up / np.linalg.norm(up))
        t = time.perf_counter()
        for _ in range(repeats):
            ours = find_floor(pts, search, up)
        t_ours = (time.perf_counter() - t) / repeats
        row = {'name': pos.name, 'n': len(pts), 'cand': len(cand), 't_ours': t_ours,
               'err_ours': _angle(ours.normal, up_true), 'inl_ours': len(ours.inliers)}
        if o3d is not None:
            pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cand))
            t = time.perf_counter()
            for _ in range(repeats):
                model, inl = pcd.segment_plane(0.05, 3, 1000)
            row['t_o3d'] = (time.perf_counter() - t) / repeats
            row['err_o3d'] = _angle(model[:3], up_true)
            row['ours_vs_o3d'] = _angle(model[:3], ours.normal)
            ours_mask = np.abs(cand @ ours.normal + ours.d) < 0.05
            o3d_mask = np.zeros(len(cand), dtype=bool)
            o3d_mask[np.asarray(inl)] = True
            row['iou'] = float((ours_mask & o3d_mask).sum() / max((ours_mask | o3d_mask).sum(), 1))
        rows.append(row)
    print('\n== floor plane fit (paper B protocol, 15 clouds of 28800 points, gravity-guided) ==')
    header = f'{"pos":6} {"cand":>6} {"ours ms":>8} {"err deg":>8}'
    if o3d is not None:
        header += f' {"o3d ms":>8} {"o3d err":>8} {"ours-o3d":>9} {"IoU":>6}'
    print(header)
    for r in rows:
        line = f'{r["name"]:6} {r["cand"]:6d} {r["t_ours"] * 1e3:8.1f} {r["err_ours"]:8.4f}'
        if o3d is not None:
            line += (f' {r["t_o3d"] * 1e3:8.1f} {r["err_o3d"]:8.4f} {r["ours_vs_o3d"]:9.4f} '
                     f'{r["iou"]:6.3f}')
        print(line)
    mean = {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k not in ('name',)}
    print(f'mean: ours {mean["t_ours"] * 1e3:.1f} ms per cloud (crop + MSAC + refit), normal '
          f'error vs truth {mean["err_ours"]:.4f} deg')
    print(f'      median normal error {np.median([r["err_ours"] for r in rows]):.4f} deg')
    if o3d is not None:
        same = [r for r in rows if r['ours_vs_o3d'] < 10.0]
        print(f'      Open3D {o3d.__version__} segment_plane(0.05 m, 3, 1000 iterations) '
              f'{mean["t_o3d"] * 1e3:.1f} ms on the same cropped points; it found another '
              f'plane (a wall, > 10 deg off) in {len(rows) - len(same)} of {len(rows)} clouds')
        print(f'      where both found the floor: normal error ours '
              f'{np.mean([r["err_ours"] for r in same]):.4f} deg, Open3D '
              f'{np.mean([r["err_o3d"] for r in same]):.4f} deg (median '
              f'{np.median([r["err_o3d"] for r in same]):.4f}); ours vs Open3D '
              f'{np.mean([r["ours_vs_o3d"] for r in same]):.4f} deg, inlier IoU '
              f'{np.mean([r["iou"] for r in same]):.3f}')
    else:
        print('Open3D not importable here: comparison skipped. To enable: python3 -m venv '
              '/tmp/o3d && /tmp/o3d/bin/pip install open3d pyyaml scipy && '
              'PYTHONPATH=$PWD /tmp/o3d/bin/python benchmarks/bench_lidar.py')


def bench_georef(n_points):
    """Georeferencing throughput on synthetic points and on the moving-platform scene."""
    print('\n== georeferencing throughput (p_nav = C(t)(R p + l) + r(t), slerp + linear) ==')
    rng = np.random.default_rng(0)
    tk = np.arange(0.0, 10.0 + 1e-9, 0.005)
    poses = PoseStream(tk, rng.normal(size=(len(tk), 3)),
                       Rotation.random(len(tk), random_state=0).as_quat())
    times = np.sort(rng.uniform(0, 10, n_points))
    pts = rng.normal(size=(n_points, 3)) * 20
    bs = Rotation.from_euler('xyz', [1, 2, 3], degrees=True).as_matrix()
    for threads in (1, 2):
        best = np.inf
        for _ in range(3):
            t = time.perf_counter()
            georeference(pts, times, poses, bs, (0.1, 0.2, 0.3), threads=threads)
            best = min(best, time.perf_counter() - t)
        print(f'{n_points} points, 200 Hz poses, {threads} thread(s): {best:.3f} s -> '
              f'{n_points / best / 1e6:.2f} M points/s (target 1 M/s)')
    scene = sim.simulate_moving_platform(3.0, range_noise_m=0.0)
    times = point_times(scene.cloud, scene.scan_start_s)
    p = xyz(scene.cloud)
    t = time.perf_counter()
    out, _, stats = georeference(p, times, scene.poses, scene.boresight, scene.lever_arm_m)
    dt = time.perf_counter() - t
    err = np.linalg.norm(out - scene.truth_world, axis=1)
    print(f'moving platform (3 s VLP-16, {len(p)} points): {len(p) / dt / 1e6:.2f} M points/s; '
          f'error vs truth (noiseless) max {err.max() * 1e3:.3f} mm, rms '
          f'{np.sqrt(np.mean(err ** 2)) * 1e3:.4f} mm')


def bench_boresight(trials):
    """Boresight error on the simulated 15-position protocol, with and without prior."""
    print('\n== boresight on the simulated 15-position protocol (truth known) ==')
    truth = sim.default_boresight()
    for label, prior, weighting in (('prior, equal weights', sim.nominal_mount(), 'equal'),
                                    ('prior, noise weights', sim.nominal_mount(), 'noise'),
                                    ('no prior, equal weights', None, 'equal')):
        errs, means, secs = [], [], []
        for seed in range(trials):
            positions = sim.positions_for_calibration(sim.simulate_protocol(truth, seed=seed))
            t = time.perf_counter()
            res = calibrate_boresight(positions, prior, weighting=weighting)
            secs.append(time.perf_counter() - t)
            errs.append(rotation_angle_deg(res.rotation, truth))
            means.append(res.mean_error_deg)
        print(f'{label:24}: rotation error mean {np.mean(errs):.4f} deg, max '
              f'{np.max(errs):.4f} deg over {trials} seeds (target < 0.05); per-position mean '
              f'{np.mean(means):.4f} deg (paper B: 0.3); {np.mean(secs):.2f} s per calibration')


def bench_box_room(trials):
    """Boresight without a prior in an empty 8 m cube: resolved by the cues, or refused."""
    from accelcal_ros.lidar.floor_assign import AmbiguousFloorError

    print('\n== no prior in an empty 8 m cube (ceiling and walls as large as the floor) ==')
    truth = sim.default_boresight()
    for origin in ((0.3, 0.2, 3.0), (0.0, 0.0, 4.0)):
        for order in ('xy', 'yx'):
            outcome, secs = [], []
            for seed in range(trials):
                positions = sim.positions_for_calibration(sim.simulate_protocol(
                    truth, room=sim.box_room(), seed=seed, scanner_origin=origin, order=order))
                t = time.perf_counter()
                try:
                    res = calibrate_boresight(positions, None)
                    outcome.append(f'{rotation_angle_deg(res.rotation, truth):.4f} deg')
                except AmbiguousFloorError as exc:
                    outcome.append(f'refused ({len(exc.candidates)} candidates)')
                secs.append(time.perf_counter() - t)
            print(f'scanner at {origin} m, tilts {order}: {", ".join(outcome)}; '
                  f'{np.mean(secs):.1f} s per calibration')


def bench_files():
    """PCD read/write speed per encoding (LZF in pure Python + numpy)."""
    print('\n== PCD files (one VLP-16 revolution, 28800 points, x y z intensity ring time) ==')
    cloud = sim.simulate_protocol(sim.default_boresight(), tilts_deg=[(0, 0)])[0].cloud
    with tempfile.TemporaryDirectory() as tmp:
        for data in ('ascii', 'binary', 'binary_compressed'):
            path = os.path.join(tmp, f'c_{data}.pcd')
            t = time.perf_counter()
            write_pcd(path, cloud, data)
            tw = time.perf_counter() - t
            t = time.perf_counter()
            read_pcd(path)
            tr = time.perf_counter() - t
            print(f'{data:18}: write {tw * 1e3:7.1f} ms, read {tr * 1e3:7.1f} ms, '
                  f'{os.path.getsize(path) / 1024:7.1f} kB')


def main():
    """Run every benchmark."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument('--quick', action='store_true')
    args = parser.parse_args()
    protocol = sim.simulate_protocol(sim.default_boresight(), seed=0)
    bench_plane_fit(protocol, 1 if args.quick else 3)
    bench_georef(500_000 if args.quick else 2_000_000)
    bench_boresight(2 if args.quick else 5)
    bench_box_room(1 if args.quick else 3)
    bench_files()


if __name__ == '__main__':
    main()
