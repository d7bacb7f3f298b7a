r"""
The package's calibrations as a tree of rigid transforms (tf2's convention; shared floor).

A :class:`FrameTransform` from ``parent`` to ``child`` maps vectors given in the child
frame into the parent frame, as every tf2 transform and ``static_transform_publisher``
do:

.. math::  v_{parent} = R\, v_{child} + t

``R`` is the child frame's axes written in the parent frame, ``t`` the child frame's
origin in the parent frame (m). How each calibration file's matrix becomes such a
transform (:func:`calibration_transforms`):

===========================================  ==========================================
edge (parent -> child)                       from the files
===========================================  ==========================================
``base_link`` -> ``imu_link``                mount parameters: ``R = Rz(yaw) Ry(pitch)
                                             Rx(roll)`` of ``imu_mount_rpy_deg``,
                                             ``t = imu_mount_xyz_m`` (identity default)
``imu_link`` -> ``<cam0>_optical_frame``     the rig file's ``imu_to_camera`` ``M`` maps
                                             IMU vectors into the reference camera
                                             (``v_cam = M v_imu``), so ``R = M^T``,
                                             ``t = 0`` (the rig file holds no offset)
``<cam0>_optical_frame`` ->                  ``R_0i`` maps reference-camera vectors into
``<cam i>_optical_frame``                    camera ``i`` (``v_i = R_0i v_0 + t_0i``), so
                                             ``R = R_0i^T``, ``t = -R_0i^T t_0i``
                                             (``t_0i`` = the camera's ``t_m``, 0 where
                                             the rig file has none)
``imu_link`` -> ``lidar_link``               the boresight ``R`` maps LiDAR vectors into
                                             the IMU frame and the lever arm ``l`` is the
                                             LiDAR origin there (paper B,
                                             ``p_imu = R p_L + l``): ``R``, ``t = l``
===========================================  ==========================================

Frame ids follow tf2: no leading ``/``, and (stricter than tf2, as ROS names) letters,
digits and ``_`` in ``/``-separated segments that do not start with a digit.
:func:`check_tree` refuses a set that is not one tree (a child with two parents, a
cycle, a frame that does not reach the root), so a broken set is never published.
"""
from dataclasses import dataclass
import re
from typing import Any, Dict, List, Optional, Sequence, Tuple

from accelcal_ros.camera.rig import Rig
from accelcal_ros.errors import InputError
from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, rotation_from_rpy_radians,
                                 rotation_matrix_from_list)
from accelcal_ros.paramspec import ParamSpec
import numpy as np
from numpy.typing import ArrayLike
from scipy.spatial.transform import Rotation

FRAME_ID_PATTERN = re.compile(r'^[A-Za-z_][A-Za-z0-9_]*(/[A-Za-z_][A-Za-z0-9_]*)*$')
"""A valid frame id: ROS name segments, no leading ``/`` (tf2 refuses or strips it)."""

OPTICAL_SUFFIX = '_optical_frame'
"""REP-103: ``<camera>_optical_frame`` is z forward, x right, y down."""
OFFSET_LIMIT_M = 1.0e4
"""Largest offset (m, each axis) of a transform this package publishes from a parameter
or an option (the IMU's mount, a LiDAR's lever arm): 10 km; beyond it a value is a
mistake (``1e308`` went onto ``/tf_static``), not a rig."""
ANGLE_LIMIT_DEG = 360.0
"""Largest roll/pitch/yaw (deg) given as a parameter or an option of a mounting."""


def check_frame_id(frame_id: str, what: str = 'frame id') -> str:
    """Return ``frame_id`` if it is a valid tf2 frame id, else raise InputError saying why."""
    if not isinstance(frame_id, str) or not frame_id:
        raise InputError(f'{what}: a frame id must be a non-empty string')
    if frame_id.startswith('/'):
        raise InputError(f'{what} {frame_id!r}: tf2 frame ids have no leading "/"')
    if not FRAME_ID_PATTERN.match(frame_id):
        raise InputError(f'{what} {frame_id!r}: not a valid frame id (letters, digits and _ '
                         'in /-separated parts, none starting with a digit)')
    return frame_id


@dataclass(frozen=True, eq=False)
class FrameTransform:
    """
    Rigid transform ``parent`` <- ``child``: ``v_parent = rotation @ v_child + translation``.

    ``rotation`` 3x3 (checked to be a rotation), ``translation`` (3,) in metres.
    """

    parent: str
    child: str
    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        """Check the frame ids and that ``rotation`` is a rotation; freeze the arrays."""
        check_frame_id(self.parent, 'parent frame')
        check_frame_id(self.child, 'child frame')
        if self.parent == self.child:
            raise InputError(f'transform {self.parent!r} -> itself: parent and child must '
                             'differ')
        r = rotation_matrix_from_list(np.asarray(self.rotation, dtype=float).reshape(-1),
                                      name=f'{self.parent} -> {self.child} rotation',
                                      tolerance=1e-4)
        t = np.asarray(self.translation, dtype=float).reshape(-1)
        if t.size != 3 or not np.all(np.isfinite(t)):
            raise InputError(f'{self.parent} -> {self.child} translation: 3 finite numbers '
                             f'(m), got {t.tolist()}')
        r.setflags(write=False)
        t = t.copy()
        t.setflags(write=False)
        object.__setattr__(self, 'rotation', r)
        object.__setattr__(self, 'translation', t)

    def apply(self, vectors: ArrayLike) -> np.ndarray:
        """Map points ``(..., 3)`` given in the child frame into the parent frame."""
        v = np.asarray(vectors, dtype=float)
        return v @ self.rotation.T + self.translation

    def quaternion_xyzw(self) -> np.ndarray:
        """Rotation as a unit quaternion ``[x, y, z, w]`` (geometry_msgs order), ``w >= 0``."""
        q = Rotation.from_matrix(np.array(self.rotation)).as_quat()  # scipy 1.11: writable
        return -q if q[3] < 0 else q


def rotation_from_quaternion_xyzw(quaternion: ArrayLike) -> np.ndarray:
    """Rotation matrix of a quaternion ``[x, y, z, w]`` (normalised; as tf2 reads it)."""
    return Rotation.from_quat(np.asarray(quaternion, dtype=float)).as_matrix()


def check_tree(transforms: Sequence[FrameTransform]) -> str:
    """
    Check that ``transforms`` form one tree; return its root frame.

    Refused with one reason (InputError): no transform, a frame that is the child of two
    transforms (duplicate frame ids), a cycle, or frames that do not all reach one root.
    """
    if not transforms:
        raise InputError('no transform to publish')
    parent_of: Dict[str, str] = {}
    for tf in transforms:
        if tf.child in parent_of:
            raise InputError(f'frame {tf.child!r} appears twice as a child (from '
                             f'{parent_of[tf.child]!r} and {tf.parent!r}): frame ids must be '
                             'unique (two cameras with one name?)')
        parent_of[tf.child] = tf.parent
    roots = set()
    for frame in parent_of:
        seen = {frame}
        while frame in parent_of:
            frame = parent_of[frame]
            if frame in seen:
                raise InputError(f'the transforms form a cycle through {frame!r}')
            seen.add(frame)
        roots.add(frame)
    if len(roots) != 1:
        raise InputError(f'the transforms form {len(roots)} separate trees (roots '
                         f'{sorted(roots)}): every frame must reach one root')
    return roots.pop()


def to_ancestor(transforms: Sequence[FrameTransform], frame: str,
                ancestor: str) -> Tuple[np.ndarray, np.ndarray]:
    """
    Compose the chain from ``frame`` up to ``ancestor`` as tf2's lookup does.

    Returns ``(R, t)`` with ``v_ancestor = R v_frame + t``; InputError if ``frame`` does not
    reach ``ancestor``.
    """
    parent = {tf.child: tf for tf in transforms}
    r, t = np.eye(3), np.zeros(3)
    current = frame
    steps = 0
    while current != ancestor:
        if current not in parent or steps > len(transforms):
            raise InputError(f'frame {frame!r} does not reach {ancestor!r}')
        tf = parent[current]
        r, t = tf.rotation @ r, tf.rotation @ t + tf.translation
        current = tf.parent
        steps += 1
    return r, t


@dataclass(frozen=True)
class FrameNames:
    """Frame ids of the calibration tree (node parameters; REP-103/105 defaults)."""

    base: str = 'base_link'
    imu: str = 'imu_link'
    lidar: str = 'lidar_link'
    camera_suffix: str = OPTICAL_SUFFIX

    def camera(self, name: str) -> str:
        """Return the optical frame id of camera ``name``."""
        return f'{name}{self.camera_suffix}'


def calibration_transforms(names: FrameNames = FrameNames(),
                           mount_xyz_m: ArrayLike = (0.0, 0.0, 0.0),
                           mount_rpy_deg: ArrayLike = (0.0, 0.0, 0.0),
                           rig: Optional[Rig] = None,
                           imu_to_camera: Optional[ArrayLike] = None,
                           camera_translations_m: Optional[Dict[str, ArrayLike]] = None,
                           boresight: Optional[ArrayLike] = None,
                           lever_arm_m: ArrayLike = (0.0, 0.0, 0.0)
                           ) -> List[FrameTransform]:
    """
    Every transform of the calibration tree (module docstring: how each follows).

    ``rig`` adds the cameras (``imu_to_camera`` overrides the rig file's, else
    :data:`~accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA`); ``camera_translations_m`` maps a
    camera name to its ``t_0i`` (m); ``boresight`` (3x3, LiDAR -> IMU) adds the LiDAR with
    ``lever_arm_m``. The result is checked to be one tree rooted at ``names.base``.
    """
    for what, frame in (('base frame', names.base), ('IMU frame', names.imu),
                        ('LiDAR frame', names.lidar)):
        check_frame_id(frame, what)
    rpy = np.asarray(mount_rpy_deg, dtype=float).reshape(-1)
    if rpy.size != 3 or not np.all(np.isfinite(rpy)):
        raise InputError(f'imu_mount_rpy_deg: 3 finite angles (deg), got {rpy.tolist()}')
    out = [FrameTransform(names.base, names.imu, rotation_from_rpy_radians(*np.radians(rpy)),
                          np.asarray(mount_xyz_m, dtype=float))]
    if rig is not None:
        out += camera_transforms(names, rig, imu_to_camera, camera_translations_m)
    if boresight is not None:
        out.append(lidar_transform(names, boresight, lever_arm_m))
    root = check_tree(out)
    if root != names.base:   # only reachable through a camera named like the base frame
        raise InputError(f'the tree is rooted at {root!r}, not {names.base!r}')
    return out


def camera_transforms(names: FrameNames, rig: Rig, imu_to_camera: Optional[ArrayLike] = None,
                      camera_translations_m: Optional[Dict[str, ArrayLike]] = None
                      ) -> List[FrameTransform]:
    """
    ``imu`` -> reference camera -> every other camera, from a rig (see the module docstring).

    ``imu_to_camera`` overrides the rig file's (else
    :data:`~accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA`); ``camera_translations_m`` maps a
    camera name to its ``t_0i`` (m), else the rig file's ``t_m``, else zero.
    """
    check_frame_id(names.imu, 'IMU frame')
    mount = imu_to_camera if imu_to_camera is not None else rig.imu_to_camera
    m = np.asarray(DEFAULT_IMU_TO_CAMERA if mount is None else mount, dtype=float)
    m = rotation_matrix_from_list(m.reshape(-1), 'imu_to_camera', tolerance=1e-4)
    translations = dict(camera_translations_m or {})
    unknown = sorted(set(translations) - set(rig.names))
    if unknown:
        raise InputError(f'camera translations for unknown camera(s) {unknown}')
    ref = names.camera(check_frame_id(rig.cameras[0].name, 'camera 0 name'))
    out = [FrameTransform(names.imu, ref, m.T, np.zeros(3))]
    for index, cam in enumerate(rig.cameras[1:], start=1):
        frame = names.camera(check_frame_id(cam.name, f'camera {index} name'))
        t_0i = np.asarray(translations.get(cam.name, np.zeros(3) if cam.t is None else cam.t),
                          dtype=float)
        out.append(FrameTransform(ref, frame, cam.R.T, -cam.R.T @ t_0i.reshape(-1)))
    check_tree(out)
    return out


def lidar_transform(names: FrameNames, boresight: ArrayLike,
                    lever_arm_m: ArrayLike = (0.0, 0.0, 0.0)) -> FrameTransform:
    """``imu`` -> ``lidar``: the boresight (LiDAR -> IMU) and the lever arm (m, IMU frame)."""
    return FrameTransform(check_frame_id(names.imu, 'IMU frame'),
                          check_frame_id(names.lidar, 'LiDAR frame'),
                          np.asarray(boresight, dtype=float), np.asarray(lever_arm_m, dtype=float))


def frame_id_reason(value: str) -> Optional[str]:
    """Return why ``value`` is not a valid frame id (a parameter validator), else None."""
    try:
        check_frame_id(value)
    except InputError as exc:
        return str(exc)
    return None


def _suffix_reason(value: str) -> Optional[str]:
    return frame_id_reason('cam' + value)


FRAME_NAME_PARAMS = (
    ParamSpec('base_frame', 'base_link', 'root frame (REP-105)', validator=frame_id_reason),
    ParamSpec('imu_frame', 'imu_link', 'the accelerometer frame', validator=frame_id_reason),
    ParamSpec('lidar_frame', 'lidar_link', 'the LiDAR frame', validator=frame_id_reason),
    ParamSpec('camera_frame_suffix', OPTICAL_SUFFIX, 'camera frame = camera name + this '
              '(REP-103 optical frame)', validator=_suffix_reason),
)
"""The frame-name parameters; nodes that publish a part of the tree declare a subset."""


def frame_name_params(*names: str) -> Tuple[ParamSpec, ...]:
    """Return the :data:`FRAME_NAME_PARAMS` called ``names`` (in that order)."""
    by_name = {spec.name: spec for spec in FRAME_NAME_PARAMS}
    return tuple(by_name[name] for name in names)


def names_from_values(values: Dict[str, Any]) -> FrameNames:
    """Return :class:`FrameNames` from parameter values (absent names keep their default)."""
    default = FrameNames()
    return FrameNames(values.get('base_frame', default.base),
                      values.get('imu_frame', default.imu),
                      values.get('lidar_frame', default.lidar),
                      values.get('camera_frame_suffix', default.camera_suffix))


CALIBRATION_FRAMES_PARAMS = (
    ParamSpec('rig_file', '', 'rig YAML (cameras, R_0i, imu_to_camera): the camera frames; '
              'empty = no cameras'),
    ParamSpec('boresight_file', '', 'boresight YAML (R or rpy_deg, LiDAR -> IMU): the LiDAR '
              'frame; empty = no LiDAR'),
    ParamSpec('lidar_lever_arm_m', [0.0, 0.0, 0.0], 'LiDAR origin in the IMU frame',
              lengths=(3,), minimum=-OFFSET_LIMIT_M, maximum=OFFSET_LIMIT_M, unit='m'),
    ParamSpec('imu_mount_xyz_m', [0.0, 0.0, 0.0], 'IMU origin in the base frame',
              lengths=(3,), minimum=-OFFSET_LIMIT_M, maximum=OFFSET_LIMIT_M, unit='m'),
    ParamSpec('imu_mount_rpy_deg', [0.0, 0.0, 0.0], 'IMU axes in the base frame (roll pitch '
              'yaw, REP-103 fixed axes)', lengths=(3,), minimum=-180.0, maximum=180.0,
              unit='deg'),
    *FRAME_NAME_PARAMS,
    ParamSpec('poll_period_s', 1.0, 'how often the files are checked for a new calibration',
              minimum=0.1, maximum=60.0, unit='s', read_only=True),
)
"""Every parameter of the ``calibration_frames`` node (see config/calibration_frames.yaml)."""


def transforms_from_parameters(values: Dict[str, Any]) -> List[FrameTransform]:
    """
    Load the files named by ``calibration_frames`` parameter ``values``; return the tree.

    Any bad file or value raises an :class:`~accelcal_ros.errors.AccelcalError` (one
    reason: the file and field, the duplicate frame, the invalid frame id), before
    anything could be published.
    """
    from accelcal_ros.boresight_file import load_boresight
    from accelcal_ros.camera.rig import load_rig

    rig = load_rig(values['rig_file']) if values['rig_file'] else None
    boresight = load_boresight(values['boresight_file']) if values['boresight_file'] else None
    return calibration_transforms(names_from_values(values), values['imu_mount_xyz_m'],
                                  values['imu_mount_rpy_deg'], rig, boresight=boresight,
                                  lever_arm_m=values['lidar_lever_arm_m'])
