"""
Camera rig: intrinsics, distortion and rotations of every camera, read from YAML.

File format (paper A: ``K_i`` and ``R_0i`` from a photogrammetric calibration)::

    cameras:
      - name: cam0            # the reference camera (carries the IMU): R = identity
        width: 1280
        height: 960
        K: [fx, 0, cx, 0, fy, cy, 0, 0, 1]     # row-major 3x3, pixels
        D: [k1, k2, p1, p2, k3]                # optional, OpenCV model (4 or 5 values)
        R: [1, 0, 0, 0, 1, 0, 0, 0, 1]         # R_0i row-major
      - name: cam1
        ...

``R`` is ``R_0i``: it maps a vector in the reference camera's optical frame (x right,
y down, z forward) into camera ``i``'s optical frame; ``R_00 = I``. Camera ``i``'s
optical axis in the reference frame is therefore the third row of ``R_0i``. Pixel
coordinates follow OpenCV: integer values at pixel centres, ``(0, 0)`` the centre of the
top-left pixel. Every error names the camera (by index and name) and the key.
"""
from dataclasses import dataclass
from typing import Tuple

from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import dump_yaml, load_yaml_mapping, write_text_atomic
from accelcal_ros.frames import rot_x, rot_y, rot_z, rotation_matrix_from_list
import numpy as np

REFERENCE_TOLERANCE = 1e-6


@dataclass(frozen=True)
class Camera:
    """One calibrated camera: size (px), ``K`` 3x3, ``D`` (5,) OpenCV, ``R`` = ``R_0i``."""

    name: str
    width: int
    height: int
    K: np.ndarray
    D: np.ndarray
    R: np.ndarray

    @property
    def optical_axis_in_reference(self):
        """Camera's optical axis (unit) in the reference camera's frame: ``R_0i^T e_z``."""
        return self.R[2].copy()

    @property
    def size(self):
        """Return ``(width, height)`` in pixels."""
        return self.width, self.height

    def has_distortion(self):
        """Return True if any distortion coefficient is non-zero."""
        return bool(np.any(self.D != 0.0))


@dataclass(frozen=True)
class Rig:
    """Cameras in rig order; camera 0 is the reference (``R_00 = I``)."""

    cameras: Tuple[Camera, ...]

    def __post_init__(self):
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

    def __len__(self):
        """Return the number of cameras."""
        return len(self.cameras)

    @property
    def names(self):
        """Return the camera names in rig order."""
        return [c.name for c in self.cameras]


def _number_list(value, count_choices, where, key):
    if not isinstance(value, (list, tuple)):
        raise InputError(f'{where}: {key} must be a list of numbers, got '
                         f'{type(value).__name__}')
    try:
        arr = np.array([float(v) for v in value], dtype=float)
    except (TypeError, ValueError):
        raise InputError(f'{where}: {key} must contain numbers only, got {value!r}') from None
    if arr.size not in count_choices:
        wanted = ' or '.join(str(n) for n in count_choices)
        raise InputError(f'{where}: {key} needs {wanted} values, got {arr.size}')
    if not np.all(np.isfinite(arr)):
        raise InputError(f'{where}: {key} contains NaN or infinity')
    return arr


def camera_from_mapping(entry, index):
    """
    Build a :class:`Camera` from one ``cameras:`` entry; errors name the camera and key.

    Raises :class:`InputError`.
    """
    if not isinstance(entry, dict):
        raise InputError(f'camera {index}: expected a mapping with name, width, height, K, '
                         f'R (and optional D), got {type(entry).__name__}')
    name = entry.get('name')
    where = f'camera {index}' + (f' ({name!r})' if name is not None else '')
    missing = [k for k in ('name', 'width', 'height', 'K', 'R') if k not in entry]
    if missing:
        raise InputError(f'{where}: missing key(s) {", ".join(missing)}')
    unknown = sorted(set(entry) - {'name', 'width', 'height', 'K', 'D', 'R'})
    if unknown:
        raise InputError(f'{where}: unknown key(s) {", ".join(unknown)}; expected name, '
                         'width, height, K, D, R')
    if not isinstance(name, str) or not name:
        raise InputError(f'{where}: name must be a non-empty string')
    size = []
    for key in ('width', 'height'):
        value = entry[key]
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 100000:
            raise InputError(f'{where}: {key} must be a positive integer, got {value!r}')
        size.append(value)
    k = _number_list(entry['K'], (9,), where, 'K').reshape(3, 3)
    if k[0, 0] <= 0 or k[1, 1] <= 0 or np.abs(k[2] - [0.0, 0.0, 1.0]).max() > 1e-9 \
            or k[1, 0] != 0.0:
        raise InputError(f'{where}: K must be [fx, s, cx, 0, fy, cy, 0, 0, 1] with fx, fy > 0, '
                         f'got {k.reshape(-1).tolist()}')
    d = np.zeros(5)
    if entry.get('D') is not None:
        given = _number_list(entry['D'], (0, 4, 5), where, 'D')
        d[:given.size] = given
    r = rotation_matrix_from_list(_number_list(entry['R'], (9,), where, 'R'),
                                  name=f'{where}: R', tolerance=1e-4)
    return Camera(name, size[0], size[1], k, d, r)


def rig_from_mapping(data, source='rig'):
    """Build a :class:`Rig` from a parsed YAML mapping (``{'cameras': [...]}``)."""
    if 'cameras' not in data:
        raise InputError(f'{source}: missing key "cameras" (a list of cameras)')
    entries = data['cameras']
    if not isinstance(entries, list) or not entries:
        raise InputError(f'{source}: "cameras" must be a non-empty list')
    return Rig(tuple(camera_from_mapping(e, i) for i, e in enumerate(entries)))


def load_rig(path):
    """Load and validate a rig YAML file; raises :class:`FileFormatError` naming the file."""
    data = load_yaml_mapping(path, what='rig file')
    try:
        return rig_from_mapping(data, source='rig file')
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None


def rig_to_mapping(rig):
    """Return the YAML-ready mapping of a rig (inverse of :func:`rig_from_mapping`)."""
    cams = []
    for cam in rig.cameras:
        cams.append({'name': cam.name, 'width': int(cam.width), 'height': int(cam.height),
                     'K': [float(x) + 0.0 for x in cam.K.reshape(-1)],
                     'D': [float(x) + 0.0 for x in cam.D],
                     'R': [float(x) + 0.0 for x in cam.R.reshape(-1)]})
    return {'cameras': cams}


def save_rig(path, rig):
    """Write a rig file atomically."""
    write_text_atomic(path, dump_yaml(rig_to_mapping(rig)))


def ring_rig(count=5, width=1280, height=960, focal_px=1100.0, step_deg=36.0,
             distortion=(0.0, 0.0, 0.0, 0.0, 0.0), mount_error_deg=0.0, seed=0,
             names=None):
    """
    Return a horizontal ring of identical cameras (for tests, the demo and the study).

    Camera 0 (the reference) looks straight ahead; the others alternate right and left in
    steps of ``step_deg`` of azimuth (order 0, +1, -1, +2, -2, ...). With
    ``mount_error_deg`` > 0 each non-reference camera gets small random extra rotations
    (roll, pitch, yaw, normal with that standard deviation), as a real rig would.
    """
    rng = np.random.default_rng(seed)
    cams = []
    k = np.array([[focal_px, 0.0, (width - 1) / 2.0],
                  [0.0, focal_px, (height - 1) / 2.0],
                  [0.0, 0.0, 1.0]])
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
        cams.append(Camera(name, int(width), int(height), k.copy(),
                           np.array(distortion, dtype=float), r))
    return Rig(tuple(cams))
