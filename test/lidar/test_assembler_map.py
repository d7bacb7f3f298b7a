"""
``cloud_assembler`` with UTM odometry: ``map`` frame at a UTM origin, save to LAZ with the CRS.

The moving-platform scene is shifted to UTM 37N magnitudes (E 412 km, N 6179 km), where a
float32 field steps 0.5 m: the published points must be in ``map`` (origin subtracted,
on the hall's surfaces to 3 mm) and the saved LAZ must hold the CRS and the absolute
coordinates to 1 mm (voxel thinning optional).
"""
import time

from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.lidar import scanner_sim as sim
from accelcal_ros.lidar.cloud import make_cloud
from accelcal_ros.lidar.map_output import choose_origin, voxel_thin, write_map_cloud
from accelcal_ros.lidar.poses import PoseStream
from accelcal_ros.lidar.scanner_sim_ros import drive_moving_platform
from accelcal_ros.rosutil.pointcloud2 import pointcloud2_to_array
from accelcal_ros.textformats import dump_yaml
import laspy
import numpy as np
import pytest

ORIGIN = np.array([412000.0, 6179000.0, 100.0])


def test_choose_origin_and_voxel_thin():
    """The origin is the parameter or the first pose rounded; thinning keeps one per voxel."""
    assert choose_origin([1.0, 2.0, 3.0], [9, 9, 9]).tolist() == [1.0, 2.0, 3.0]
    rounded = choose_origin([], [412345.6, 6179876.5, 151.0])
    assert rounded.tolist() == [412000.0, 6180000.0, 200.0]
    pts = np.array([[0.01, 0.01, 0.0], [0.02, 0.03, 0.0], [0.2, 0.0, 0.0], [0.21, 0.01, 0.0]])
    cloud = make_cloud(pts, time=np.arange(4.0), time_field='timestamp', double=True)
    thin = voxel_thin(cloud, 0.1)
    assert thin['timestamp'].tolist() == [0.0, 2.0]
    assert len(voxel_thin(cloud, 0.0)) == 4


def test_write_map_cloud_laz(tmp_path):
    """Saved LAZ: CRS, absolute coordinates to 1 mm, times; LAS without a CRS refused."""
    rng = np.random.default_rng(0)
    pts = ORIGIN + rng.uniform(-50, 50, (1000, 3))
    cloud = make_cloud(pts, rng.uniform(0, 255, 1000), rng.integers(0, 16, 1000),
                       1.7e9 + np.arange(1000) * 1e-3, 'timestamp', double=True)
    assert write_map_cloud(str(tmp_path / 'm.laz'), cloud, 'EPSG:32637') == 1000
    las = laspy.read(tmp_path / 'm.laz')
    assert las.header.parse_crs().to_epsg() == 32637
    assert np.abs(np.stack([las.x, las.y, las.z], 1) - pts).max() <= 0.0005 + 1e-9
    from accelcal_ros.errors import InputError

    with pytest.raises(InputError, match='map_crs'):
        write_map_cloud(str(tmp_path / 'n.las'), cloud, '')


@pytest.mark.graph
def test_cloud_assembler_publishes_map_frame_and_saves_laz(graph, tmp_path):
    """UTM odometry in; map-frame points out (origin logged); save writes the LAZ."""
    from sensor_msgs.msg import PointCloud2
    from std_srvs.srv import Trigger

    scene = sim.simulate_moving_platform(0.6, seed=4, range_noise_m=0.0)
    scene.poses = PoseStream(scene.poses.t, scene.poses.position + ORIGIN,
                             scene.poses.quat_xyzw)
    bs = tmp_path / 'bs.yaml'
    write_text_atomic(bs, dump_yaml({'R': scene.boresight.ravel().tolist()}))
    laz = tmp_path / 'map.laz'
    proc = graph.start('cloud_assembler', params={
        'boresight_file': str(bs), 'lever_arm_m': scene.lever_arm_m.tolist(),
        'output_file': str(laz), 'queue_depth': 50, 'map_crs': 'EPSG:32637',
        'map_origin': ORIGIN.tolist(), 'save_voxel_m': 0.0})
    collector = graph.collect(PointCloud2, 'points_georef', 50)
    sent = drive_moving_platform(graph.node, scene, pace=0.5)
    deadline = time.monotonic() + 15.0
    while len(collector.snapshot()[0]) < sent and time.monotonic() < deadline:
        time.sleep(0.1)
    msgs = collector.snapshot()[0]
    assert msgs
    assert msgs[0].header.frame_id == 'map'
    pts = np.vstack([np.stack([c['x'], c['y'], c['z']], axis=1)
                     for c in map(pointcloud2_to_array, msgs)])
    assert np.percentile(scene.room.surface_distance(pts), 99.9) < 0.003
    response = graph.call(Trigger, 'cloud_assembler/save', timeout=20.0)
    assert response.success, response.message + proc.output()
    las = laspy.read(laz)
    assert las.header.parse_crs().to_epsg() == 32637
    local = np.stack([las.x, las.y, las.z], axis=1) - ORIGIN
    assert len(local) >= len(pts)
    assert np.percentile(scene.room.surface_distance(local), 99.9) < 0.003
    assert 'E 412000.000 N 6179000.000' in proc.output()
