"""The calibration frame tree: tf2's convention checked against the files' own geometry."""
from accelcal_ros.camera.rig import ring_rig
from accelcal_ros.errors import InputError
from accelcal_ros.frame_tree import (calibration_transforms, check_frame_id, check_tree,
                                     FrameNames, FrameTransform, to_ancestor)
from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, down_in_camera, rot_x, rot_z,
                                 rotation_from_rpy_radians)
from accelcal_ros.lidar.georef import georeference
from accelcal_ros.lidar.poses import PoseStream
import numpy as np
import pytest


def _tree(**kwargs):
    transforms = calibration_transforms(**kwargs)
    return transforms, {tf.child: tf for tf in transforms}


def test_camera_axes_land_where_the_rig_says_they_look():
    """Ring rig, default mount: camera i's optical axis is body azimuth -slot*36 deg."""
    rig = ring_rig(5, step_deg=36.0)
    transforms, _ = _tree(rig=rig)
    assert check_tree(transforms) == 'base_link'
    for i, cam in enumerate(rig.cameras):
        slot = (i + 1) // 2 * (1 if i % 2 else -1)       # ring_rig: right is +
        r, t = to_ancestor(transforms, f'{cam.name}_optical_frame', 'imu_link')
        azimuth = np.radians(slot * 36.0)                 # body y is left: right = -y
        assert np.allclose(r @ [0.0, 0.0, 1.0], [np.cos(azimuth), -np.sin(azimuth), 0.0],
                           atol=1e-12)
        assert np.allclose(r @ [0.0, 1.0, 0.0], [0.0, 0.0, -1.0], atol=1e-12)  # y down
        assert np.allclose(t, 0.0)


@pytest.mark.parametrize('seed', [0, 1, 2])
def test_gravity_in_the_reference_camera_is_the_packages_down_in_camera(seed):
    """imu_link -> camera 0 inverts imu_to_camera: frames.down_in_camera agrees."""
    rng = np.random.default_rng(seed)
    mount = rotation_from_rpy_radians(*rng.uniform(-np.pi, np.pi, 3) * [1, 0.5, 1])
    imu_to_camera = mount @ DEFAULT_IMU_TO_CAMERA
    rig = ring_rig(3, imu_to_camera=imu_to_camera)
    transforms, _ = _tree(rig=rig)
    r, _ = to_ancestor(transforms, 'cam0_optical_frame', 'imu_link')
    for roll, pitch in rng.uniform(-1.2, 1.2, (5, 2)):
        down_cam = down_in_camera(roll, pitch, imu_to_camera)
        down_body = -np.array([-np.sin(pitch), np.sin(roll) * np.cos(pitch),
                               np.cos(roll) * np.cos(pitch)])
        assert np.allclose(r @ down_cam, down_body, atol=1e-12)


def test_camera_translation_puts_the_camera_origin_where_the_extrinsics_say():
    """X_i = R_0i X_0 + t_0i: camera i's origin (X_i = 0) is at -R_0i^T t_0i in camera 0."""
    rig = ring_rig(3, mount_error_deg=2.0, seed=4)
    t01 = np.array([0.1, -0.02, 0.03])
    transforms, by_child = _tree(rig=rig, camera_translations_m={'cam1': t01})
    tf = by_child['cam1_optical_frame']
    point_0 = np.array([0.4, -0.3, 2.0])
    point_1 = rig.cameras[1].R @ point_0 + t01          # the extrinsics' own model
    assert np.allclose(tf.apply(point_1), point_0, atol=1e-12)


def test_lidar_edge_is_the_georeferencing_model():
    """imu_link -> lidar_link maps a LiDAR point as georef does at the identity pose."""
    boresight = rotation_from_rpy_radians(0.02, -0.03, 1.5)
    lever = np.array([0.3, -0.1, 0.25])
    _, by_child = _tree(boresight=boresight, lever_arm_m=lever)
    points = np.random.default_rng(0).normal(size=(20, 3)) * 5.0
    times = np.linspace(0.0, 1.0, 20)
    poses = PoseStream(np.array([0.0, 1.0]), np.zeros((2, 3)),
                       np.tile([0.0, 0.0, 0.0, 1.0], (2, 1)))
    expected = georeference(points, times, poses, boresight, lever)[0]
    assert np.allclose(by_child['lidar_link'].apply(points), expected, atol=1e-12)


def test_imu_mount_parameters_and_composition_to_base():
    """base_link -> imu_link from xyz/rpy like static_transform_publisher; chains compose."""
    transforms, by_child = _tree(mount_xyz_m=(0.1, 0.2, 0.3), mount_rpy_deg=(90.0, 0.0, 0.0),
                                 boresight=rot_z(0.5), lever_arm_m=(1.0, 0.0, 0.0))
    imu = by_child['imu_link']
    assert np.allclose(imu.apply([0.0, 1.0, 0.0]) - imu.translation, [0.0, 0.0, 1.0])
    r, t = to_ancestor(transforms, 'lidar_link', 'base_link')
    v = np.array([1.0, 2.0, 3.0])
    assert np.allclose(r @ v + t, imu.apply(by_child['lidar_link'].apply(v)), atol=1e-12)


def test_quaternion_is_the_rotation():
    """quaternion_xyzw round-trips through scipy and has w >= 0."""
    tf = FrameTransform('a', 'b', rot_x(2.5) @ rot_z(-2.0), [0, 0, 0])
    q = tf.quaternion_xyzw()
    assert q[3] >= 0 and abs(np.linalg.norm(q) - 1.0) < 1e-12
    from accelcal_ros.frame_tree import rotation_from_quaternion_xyzw
    assert np.allclose(rotation_from_quaternion_xyzw(q), tf.rotation, atol=1e-12)


@pytest.mark.parametrize('frame_id, reason', [
    ('', 'non-empty'), ('/base_link', 'leading'), ('cam 0', 'not a valid'),
    ('0cam', 'not a valid'), ('a//b', 'not a valid')])
def test_invalid_frame_ids_are_refused_with_the_reason(frame_id, reason):
    """tf2 frame ids: no leading slash, ROS name characters."""
    with pytest.raises(InputError, match=reason):
        check_frame_id(frame_id)
    with pytest.raises(InputError, match=reason):
        calibration_transforms(FrameNames(imu=frame_id))


def test_bad_trees_are_refused():
    """Duplicate child, cycle, two roots, not a rotation, a camera name not a frame id."""
    eye = np.eye(3)
    with pytest.raises(InputError, match='twice as a child'):
        check_tree([FrameTransform('a', 'b', eye, [0, 0, 0]),
                    FrameTransform('c', 'b', eye, [0, 0, 0])])
    with pytest.raises(InputError, match='cycle'):
        check_tree([FrameTransform('a', 'b', eye, [0, 0, 0]),
                    FrameTransform('b', 'a', eye, [0, 0, 0])])
    with pytest.raises(InputError, match='separate trees'):
        check_tree([FrameTransform('a', 'b', eye, [0, 0, 0]),
                    FrameTransform('c', 'd', eye, [0, 0, 0])])
    with pytest.raises(InputError, match='not a rotation'):
        FrameTransform('a', 'b', 2 * eye, [0, 0, 0])
    with pytest.raises(InputError, match='camera 1 name'):
        calibration_transforms(rig=ring_rig(2, names=['cam0', 'cam one']))
    with pytest.raises(InputError, match='cycle'):   # a camera named like the IMU frame
        calibration_transforms(FrameNames(camera_suffix=''),
                               rig=ring_rig(2, names=['a', 'imu_link']))
