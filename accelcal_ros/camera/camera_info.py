"""
camera_info files: the YAML of ROS's ``camera_calibration_parsers`` (shared floor).

What a camera driver loads as its ``camera_info_url`` and ``camera_calibration`` writes::

    image_width: 1280
    image_height: 960
    camera_name: cam0
    camera_matrix: {rows: 3, cols: 3, data: [fx, 0, cx, 0, fy, cy, 0, 0, 1]}
    distortion_model: plumb_bob          # or rational_polynomial, equidistant
    distortion_coefficients: {rows: 1, cols: 5, data: [k1, k2, p1, p2, k3]}
    rectification_matrix: {rows: 3, cols: 3, data: [1, 0, 0, 0, 1, 0, 0, 0, 1]}
    projection_matrix: {rows: 3, cols: 4, data: [fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0]}

For a single (not stereo) camera the rectification is the identity and the projection
matrix is ``[K | 0]``. Pixel coordinates follow OpenCV in both (as the package's camera
model does). The reader checks the file against :data:`SCHEMA` (the keys
camera_calibration_parsers reads; ``image_width``, ``image_height`` and ``camera_matrix``
required, any other key refused), each matrix's ``rows`` x ``cols`` against its data, and
names the file and key of whatever is wrong.
"""
import os
from typing import Any, Dict, Mapping, Sequence, Tuple, Union

from accelcal_ros.camera.distortion import DISTORTION_MODELS
from accelcal_ros.camera.model import camera_model_from_mapping, CameraModel
from accelcal_ros.camera.rig import Rig, RigCamera
from accelcal_ros.errors import FileFormatError, InputError
from accelcal_ros.fileio import write_text_atomic
from accelcal_ros.schema import check_mapping, is_integer, is_text, Key, numbers, one_of
from accelcal_ros.textformats import dump_yaml, load_yaml_mapping
import numpy as np

PathLike = Union[str, 'os.PathLike[str]']

_SHAPES = {'camera_matrix': (3, 3), 'rectification_matrix': (3, 3),
           'projection_matrix': (3, 4)}


_MATRIX = {'rows': Key('an integer', is_integer, required=True),
           'cols': Key('an integer', is_integer, required=True),
           'data': Key('a list of numbers', numbers(), required=True)}
SCHEMA = {
    'image_width': Key('an integer (px)', is_integer, required=True),
    'image_height': Key('an integer (px)', is_integer, required=True),
    'camera_name': Key('text', is_text),
    'camera_matrix': Key('{rows: 3, cols: 3, data: [9 numbers]}', required=True,
                         schema=_MATRIX),
    'distortion_model': Key(f'one of {", ".join(DISTORTION_MODELS)}',
                            one_of(*DISTORTION_MODELS)),
    'distortion_coefficients': Key('{rows: 1, cols: N, data: [N numbers]}', schema=_MATRIX),
    'rectification_matrix': Key('{rows: 3, cols: 3, data: [9 numbers]}', schema=_MATRIX),
    'projection_matrix': Key('{rows: 3, cols: 4, data: [12 numbers]}', schema=_MATRIX),
}
"""Every key of a camera_info file (camera_calibration_parsers' YAML) and its type."""


def _matrix(rows: int, cols: int, values: np.ndarray) -> Dict[str, Any]:
    return {'rows': rows, 'cols': cols, 'data': [float(v) + 0.0 for v in values.reshape(-1)]}


def camera_info_mapping(name: str, model: CameraModel) -> Dict[str, Any]:
    """Return the camera_calibration_parsers mapping of camera ``name`` (single camera)."""
    k = np.asarray(model.K, dtype=float)
    d = np.asarray(model.D, dtype=float)
    return {
        'image_width': int(model.width),
        'image_height': int(model.height),
        'camera_name': str(name),
        'camera_matrix': _matrix(3, 3, k),
        'distortion_model': model.distortion_model,
        'distortion_coefficients': _matrix(1, d.size, d),
        'rectification_matrix': _matrix(3, 3, np.eye(3)),
        'projection_matrix': _matrix(3, 4, np.hstack([k, np.zeros((3, 1))])),
    }


def save_camera_info(path: PathLike, name: str, model: CameraModel) -> None:
    """Write camera ``name``'s camera_info YAML atomically."""
    write_text_atomic(path, dump_yaml(camera_info_mapping(name, model)))


def _check_shape(data: Mapping, key: str, shape: Tuple[int, int]) -> None:
    entry = data.get(key)
    if entry is None:
        return
    if not isinstance(entry, Mapping) or 'data' not in entry:
        raise InputError(f'{key}: expected a mapping with rows, cols and data')
    rows, cols = entry.get('rows', shape[0]), entry.get('cols', shape[1])
    if (rows, cols) != shape:
        raise InputError(f'{key}: must be {shape[0]}x{shape[1]}, says {rows}x{cols}')
    values = entry['data']
    if not isinstance(values, list) or len(values) != shape[0] * shape[1]:
        count = len(values) if isinstance(values, list) else 'no list of'
        raise InputError(f'{key}: {shape[0]}x{shape[1]} needs {shape[0] * shape[1]} values, '
                         f'got {count}')


def camera_info_from_mapping(data: Mapping) -> Tuple[str, CameraModel]:
    """Return ``(camera_name, CameraModel)`` of a parsed camera_info mapping (InputError)."""
    check_mapping(data, SCHEMA, 'a camera_info file')
    for key, shape in _SHAPES.items():
        _check_shape(data, key, shape)
    d = data.get('distortion_coefficients')
    if isinstance(d, Mapping) and isinstance(d.get('data'), list):
        rows, cols = d.get('rows', 1), d.get('cols', len(d['data']))
        if not all(isinstance(v, int) and not isinstance(v, bool) for v in (rows, cols)):
            raise InputError(f'distortion_coefficients: rows and cols must be integers, got '
                             f'{rows!r} x {cols!r}')
        if rows * cols != len(d['data']):
            raise InputError(f'distortion_coefficients: {rows}x{cols} but '
                             f'{len(d["data"])} values')
    name = data.get('camera_name', '')
    if not isinstance(name, str):
        raise InputError(f'camera_name must be a string, got {name!r}')
    return name, camera_model_from_mapping(data, 'camera_info')


def load_camera_info(path: PathLike) -> Tuple[str, CameraModel]:
    """Read a camera_info YAML; return ``(camera_name, CameraModel)`` (FileFormatError)."""
    data = load_yaml_mapping(path, 'camera_info file')
    try:
        return camera_info_from_mapping(data)
    except InputError as exc:
        raise FileFormatError(path, str(exc)) from None


def rig_with_models(rig: Rig, models: Sequence[CameraModel],
                    sources: Sequence[str]) -> Rig:
    """
    Return ``rig`` with each camera's intrinsics replaced by ``models`` (rig order).

    Each model must have the size of the camera's images as the rig file states it (what
    the image subscriptions check every frame against); ``sources`` name where each model
    came from (a topic) for the error.
    """
    if len(models) != len(rig) or len(sources) != len(rig):
        raise InputError(f'{len(models)} camera_info(s) for a rig of {len(rig)} cameras '
                         f'({", ".join(rig.names)})')
    cams = []
    for cam, model, source in zip(rig.cameras, models, sources):
        if model.size != cam.size:
            raise InputError(f'{source}: camera_info is {model.width}x{model.height} but '
                             f'the images of camera {cam.name} are {cam.width}x{cam.height} (the '
                             'rig file): wrong topic, or the driver crops or bins?')
        cams.append(RigCamera.from_model(cam.name, model, cam.R, cam.t))
    return Rig(tuple(cams), rig.imu_to_camera)
