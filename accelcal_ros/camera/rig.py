"""
Camera rig file: every camera's model and rotation, and the IMU mounting (shared floor).

The panorama reads it, the rig calibration writes it, ``accelcal p2p-solve`` takes its
mounting; so it lives here, below every feature.

File format (paper A: ``K_i`` and ``R_0i`` from a photogrammetric calibration)::

    cameras:
      - name: cam0            # the reference camera (carries the IMU): R = identity
        width: 1280
        height: 960
        K: [fx, 0, cx, 0, fy, cy, 0, 0, 1]     # row-major 3x3, pixels
        D: [k1, k2, p1, p2, k3]                # optional, OpenCV model (4 or 5 values)
        distortion_model: plumb_bob            # optional (written only when not plumb_bob)
        R: [1, 0, 0, 0, 1, 0, 0, 0, 1]         # R_0i row-major
        t_m: [0, 0, 0]                         # optional: t_0i (m), X_i = R_0i X_0 + t_0i
      - name: cam1
        ...
    imu_to_camera: [...]      # optional: 9 values row-major, IMU body -> reference optical

A camera entry is a camera model (:class:`~accelcal_ros.camera.CameraModel`, its
mapping form: ``width``, ``height``, ``K``, ``D``, ``distortion_model``) plus ``name``
and ``R``. ``t_m`` (optional, m) is ``t_0i`` of ``X_i = R_0i X_0 + t_0i`` (the rig calibration
writes it; the stitcher ignores it, the frame tree places the camera with it).
``R`` is ``R_0i``: it maps a vector in the reference camera's optical frame
(x right, y down, z forward) into camera ``i``'s optical frame; ``R_00 = I``. Camera
``i``'s optical axis in the reference frame is therefore the third row of ``R_0i``.
``imu_to_camera`` (:data:`accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA` when absent, as the
nodes' parameter of that name) maps IMU body vectors (REP-103) into the reference
camera's optical frame. Pixel coordinates follow OpenCV: integer values at pixel
centres, ``(0, 0)`` the centre of the top-left pixel. Every error names the camera (by
index and name) and the key.
"""
from dataclasses import dataclass
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

from accelcal_ros.camera.distortion import PLUMB_BOB
from accelcal_ros.camera.model import camera_model_from_mapping, CameraModel
from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.frames import (DEFAULT_IMU_TO_CAMERA, rot_x, rot_y, rot_z,
                                 rotation_matrix_from_list)
from accelcal_ros.schema import check_mapping, Key
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping, yaml_number
import numpy as np

REFERENCE_TOLERANCE = 1e-6
SAME_ROTATION_TOLERANCE = 1e-6
"""Largest element difference between two ``R`` taken as the same rotation (a rig whose
cameras all share one ``R`` is refused: its file lost the rotations)."""


@dataclass(frozen=True, eq=False, init=False)
class RigCamera:
    """
    One camera of the rig: its ``name``, its :class:`CameraModel` and ``R`` = ``R_0i``.

    Built as ``RigCamera(name, width, height, K, D, R[, distortion_model])`` or with
    :meth:`from_model`; ``width``, ``height``, ``K``, ``D`` read through to the model.
    """

    name: str
    model: CameraModel
    R: np.ndarray
    t: Optional[np.ndarray] = None
    """``t_0i`` (m) where known: ``X_i = R_0i X_0 + t_0i`` (the frame tree uses it)."""

    def __init__(self, name: str, width: int, height: int, K: np.ndarray,
                 D: Sequence[float] = (), R: Optional[np.ndarray] = None,
                 distortion_model: str = PLUMB_BOB) -> None:
        model = CameraModel(width, height, K, np.asarray(D, dtype=float), distortion_model)
        self._set(name, model, np.eye(3) if R is None else R)

    def _set(self, name: str, model: CameraModel, r: np.ndarray,
             t: Optional[np.ndarray] = None) -> None:
        r = np.array(r, dtype=float).reshape(3, 3)
        r.setflags(write=False)
        object.__setattr__(self, 'name', str(name))
        object.__setattr__(self, 'model', model)
        object.__setattr__(self, 'R', r)
        if t is not None:
            t = np.array(t, dtype=float).reshape(3)
            t.setflags(write=False)
        object.__setattr__(self, 't', t)

    @classmethod
    def from_model(cls, name: str, model: CameraModel, r: np.ndarray,
                   t: Optional[np.ndarray] = None) -> 'RigCamera':
        """Return the rig camera ``name`` with ``model``, ``R_0i = r`` (and ``t_0i = t``)."""
        cam = cls.__new__(cls)
        cam._set(name, model, r, t)
        return cam

    @property
    def width(self) -> int:
        """Return the image width in pixels."""
        return self.model.width

    @property
    def height(self) -> int:
        """Return the image height in pixels."""
        return self.model.height

    @property
    def K(self) -> np.ndarray:  # noqa: N802 - the usual name of the intrinsic matrix
        """Intrinsic matrix 3x3 (px)."""
        return self.model.K

    @property
    def D(self) -> np.ndarray:  # noqa: N802 - the usual name of the distortion vector
        """Distortion coefficients of :attr:`distortion_model`."""
        return self.model.D

    @property
    def distortion_model(self) -> str:
        """Lens model name (``plumb_bob``...)."""
        return self.model.distortion_model

    @property
    def optical_axis_in_reference(self) -> np.ndarray:
        """Camera's optical axis (unit) in the reference camera's frame: ``R_0i^T e_z``."""
        return self.R[2].copy()

    @property
    def size(self) -> Tuple[int, int]:
        """Return ``(width, height)`` in pixels."""
        return self.model.size

    def has_distortion(self) -> bool:
        """Return True if any distortion coefficient is non-zero."""
        return self.model.has_distortion()


@dataclass(frozen=True, eq=False)
class Rig:
    """
    Cameras in rig order; camera 0 is the reference (``R_00 = I``).

    ``imu_to_camera`` (3x3 rotation, IMU body -> reference camera optical frame) is the
    file's value, or None when the file has none (the caller's default then applies).
    """

    cameras: Tuple[RigCamera, ...]
    imu_to_camera: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        """Check there is at least one camera, names are unique, camera 0 is the reference."""
        cams = tuple(self.cameras)
        object.__setattr__(self, 'cameras', cams)
        if not cams:
            raise InputError('rig has no cameras')
        names = [c.name for c in cams]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise InputError(f'rig: camera names must be unique, repeated: {duplicates}')
        if np.abs(cams[0].R - np.eye(3)).max() > REFERENCE_TOLERANCE:
            raise InputError(f'camera 0 ({cams[0].name!r}) is the reference camera (it '
                             'carries the IMU): its R must be the identity (R_00 = I); '
                             'reorder the cameras or express R relative to it')
        if len(cams) > 1 and all(np.abs(c.R - cams[0].R).max() <= SAME_ROTATION_TOLERANCE
                                 for c in cams[1:]):
            raise InputError(f'all {len(cams)} cameras of the rig have the same R (they would '
                             "all look the same way): R must be each camera's rotation R_0i "
                             'from the rig calibration (accelcal rig-calibrate); was it left at '
                             'the identity?')
        if self.imu_to_camera is not None:
            mount = rotation_matrix_from_list(np.asarray(self.imu_to_camera, dtype=float),
                                              name='imu_to_camera', tolerance=1e-4)
            mount.setflags(write=False)
            object.__setattr__(self, 'imu_to_camera', mount)

    def __len__(self) -> int:
        """Return the number of cameras."""
        return len(self.cameras)

    @property
    def names(self) -> list:
        """Return the camera names in rig order."""
        return [c.name for c in self.cameras]

    def with_imu_to_camera(self, imu_to_camera: Optional[np.ndarray]) -> 'Rig':
        """Return this rig with another ``imu_to_camera`` (e.g. a command-line override)."""
        return Rig(self.cameras, imu_to_camera)


CAMERA_ENTRY_KEYS = ('name', 'width', 'height', 'K', 'D', 'distortion_model', 'R', 't_m')
"""Keys of one ``cameras:`` entry (``D``, ``distortion_model`` and ``t_m`` optional)."""
CAMERA_SCHEMA = {key: Key('see the module text (checked by the camera model)',
                          required=key in ('name', 'width', 'height', 'K', 'R'))
                 for key in CAMERA_ENTRY_KEYS}
"""The keys of a camera entry for :func:`~accelcal_ros.schema.check_mapping` (the values
are checked, naming the camera, by :func:`camera_from_mapping`)."""
RIG_SCHEMA = {'cameras': Key('a non-empty list of cameras', required=True),
              'imu_to_camera': Key('9 numbers (a rotation, row-major)')}
"""The top-level keys of a rig file."""


def _number_list(value: Any, count_choices: Sequence[int], where: str,
                 key: str) -> np.ndarray:
    if not isinstance(value, (list, tuple)):
        raise InputError(f'{where}: {key} must be a list of numbers, got '
                         f'{type(value).__name__}')
    numbers = [yaml_number(v) for v in value]
    if any(v is None for v in numbers):
        raise InputError(f'{where}: {key} must contain numbers only, got {value!r}')
    arr = np.array(numbers, dtype=float)
    if arr.size not in count_choices:
        wanted = ' or '.join(str(n) for n in count_choices)
        raise InputError(f'{where}: {key} needs {wanted} values, got {arr.size}')
    if not np.all(np.isfinite(arr)):
        raise InputError(f'{where}: {key} contains NaN or infinity')
    return arr


def camera_from_mapping(entry: Any, index: int) -> RigCamera:
    """
    Build a :class:`RigCamera` from one ``cameras:`` entry; errors name the camera and key.

    Raises :class:`InputError`.
    """
    if not isinstance(entry, dict):
        raise InputError(f'camera {index}: expected a mapping with name, width, height, K, '
                         f'R (and optional D), got {type(entry).__name__}')
    name = entry.get('name')
    where = f'camera {index}' + (f' ({name!r})' if name is not None else '')
    try:
        check_mapping(entry, CAMERA_SCHEMA, 'a camera entry')
    except InputError as exc:
        raise InputError(f'{where}: {exc}') from None
    if not isinstance(name, str) or not name:
        raise InputError(f'{where}: name must be a non-empty string')
    model = camera_model_from_mapping(entry, where)
    r = rotation_matrix_from_list(_number_list(entry['R'], (9,), where, 'R'),
                                  name=f'{where}: R', tolerance=1e-4)
    t = _number_list(entry['t_m'], (3,), where, 't_m') if entry.get('t_m') is not None else None
    return RigCamera.from_model(name, model, r, t)


def rig_from_mapping(data: Mapping, source: str = 'rig') -> Rig:
    """Build a :class:`Rig` from a parsed YAML mapping (``cameras``, ``imu_to_camera``)."""
    try:
        check_mapping(data, RIG_SCHEMA, 'a rig file')
    except InputError as exc:
        raise InputError(f'{source}: {exc}') from None
    entries = data['cameras']
    if not isinstance(entries, list) or not entries:
        raise InputError(f'{source}: "cameras" must be a non-empty list')
    mount = None
    if data.get('imu_to_camera') is not None:
        values = _number_list(data['imu_to_camera'], (9,), source, 'imu_to_camera')
        mount = rotation_matrix_from_list(values, name=f'{source}: imu_to_camera',
                                          tolerance=1e-4)
    return Rig(tuple(camera_from_mapping(e, i) for i, e in enumerate(entries)), mount)


def load_rig(path: Any) -> Rig:
    """Load and validate a rig YAML file; raises :class:`FileFormatError` naming the file."""
    data = load_yaml_mapping(path, what='rig file')
    try:
        return rig_from_mapping(data, source='rig file')
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None


def rig_to_mapping(rig: Rig) -> Dict[str, Any]:
    """Return the YAML-ready mapping of a rig (inverse of :func:`rig_from_mapping`)."""
    cams = []
    for cam in rig.cameras:
        entry: Dict[str, Any] = {'name': cam.name}
        entry.update(cam.model.to_mapping())
        if entry['distortion_model'] == PLUMB_BOB:
            del entry['distortion_model']
        entry['R'] = [float(x) + 0.0 for x in cam.R.reshape(-1)]
        if cam.t is not None:
            entry['t_m'] = [float(x) + 0.0 for x in cam.t]
        cams.append(entry)
    out: Dict[str, Any] = {'cameras': cams}
    if rig.imu_to_camera is not None:
        out['imu_to_camera'] = [float(x) + 0.0 for x in rig.imu_to_camera.reshape(-1)]
    return out


def save_rig(path: Any, rig: Rig) -> None:
    """Write a rig file atomically."""
    write_text_atomic(path, dump_yaml(rig_to_mapping(rig)))


def resolve_imu_to_camera(rig: Optional[Rig], override: Optional[Sequence[float]] = None,
                          name: str = '--imu-to-camera') -> Tuple[np.ndarray, str]:
    """
    Return ``(imu_to_camera, source)``: an explicit value wins over the rig file's.

    ``override`` (9 row-major values, validated as a rotation, errors naming ``name``)
    if given, else the rig's ``imu_to_camera``, else
    :data:`~accelcal_ros.frames.DEFAULT_IMU_TO_CAMERA`; ``source`` says which
    (``name``, ``'rig file'`` or ``'default'``).
    """
    if override is not None:
        values = np.asarray(override, dtype=float).reshape(-1)
        if values.size == 9 and np.all(np.isfinite(values)) and np.abs(values).max() > 1.001:
            raise InputError(f'{name}: not a rotation matrix (entries beyond +-1)')
        return rotation_matrix_from_list(values, name=name, tolerance=1e-4), name
    if rig is not None and rig.imu_to_camera is not None:
        return rig.imu_to_camera.copy(), 'rig file'
    return DEFAULT_IMU_TO_CAMERA.copy(), 'default'


def ring_rig(count: int = 5, width: int = 1280, height: int = 960, focal_px: float = 1100.0,
             step_deg: float = 36.0, distortion: Sequence[float] = (0.0, 0.0, 0.0, 0.0, 0.0),
             mount_error_deg: float = 0.0, seed: int = 0,
             names: Optional[Sequence[str]] = None,
             imu_to_camera: Optional[np.ndarray] = None) -> Rig:
    """
    Return a horizontal ring of identical cameras (for tests, the demo and the study).

    Camera 0 (the reference) looks straight ahead; the others alternate right and left in
    steps of ``step_deg`` of azimuth (order 0, +1, -1, +2, -2, ...). With
    ``mount_error_deg`` > 0 each non-reference camera gets small random extra rotations
    (roll, pitch, yaw, normal with that standard deviation), as a real rig would.
    """
    rng = np.random.default_rng(seed)
    cams = []
    k = np.array([[focal_px, 0.0, (width - 1) / 2.0], [0.0, focal_px, (height - 1) / 2.0],
                  [0.0, 0.0, 1.0]])
    model = CameraModel(int(width), int(height), k, np.array(distortion, dtype=float))
    for i in range(count):
        slot = (i + 1) // 2 * (1 if i % 2 else -1)
        azimuth = np.radians(slot * step_deg)
        # camera i looks at azimuth a (right +): its axis in the reference frame is
        # [sin a, 0, cos a] = rot_y(a) e_z, so R_0i = rot_y(a)^T.
        r = rot_y(azimuth).T
        if i and mount_error_deg > 0:
            e = np.radians(rng.normal(0.0, mount_error_deg, 3))
            r = rot_z(e[0]) @ rot_x(e[1]) @ rot_y(e[2]) @ r
        name = names[i] if names else f'cam{i}'
        cams.append(RigCamera.from_model(name, model, r))
    return Rig(tuple(cams), imu_to_camera)
