"""
sensor_msgs/Image <-> numpy arrays: the part of cv_bridge this package needs.

Supported encodings: ``rgb8``, ``bgr8``, ``mono8`` (and ``mono16`` for reading). Images
are returned as OpenCV-ordered arrays: ``bgr8`` -> HxWx3 BGR, ``rgb8`` -> HxWx3 RGB
unless ``want='bgr8'``, ``mono8`` -> HxW. Row padding (``step`` larger than
``width * channels``) and big-endian 16-bit data are handled. Anything else raises
:class:`~accelcal_ros.errors.InputError` with the encoding named.
"""
from accelcal_ros.errors import InputError
import numpy as np

_CHANNELS = {'rgb8': 3, 'bgr8': 3, 'mono8': 1, 'mono16': 1}
_DTYPES = {'rgb8': np.uint8, 'bgr8': np.uint8, 'mono8': np.uint8, 'mono16': np.uint16}
SUPPORTED_ENCODINGS = ('rgb8', 'bgr8', 'mono8')


def image_msg_to_array(msg, want=None, encodings=SUPPORTED_ENCODINGS):
    """
    Array view of a sensor_msgs/Image (copied, contiguous).

    ``want`` in (None, 'bgr8', 'rgb8', 'mono8') converts colour order / to grey.
    """
    enc = msg.encoding.lower()
    if enc not in encodings:
        raise InputError(f'unsupported image encoding {msg.encoding!r}; '
                         f'supported: {", ".join(encodings)}')
    channels = _CHANNELS[enc]
    dtype = np.dtype(_DTYPES[enc])
    if msg.is_bigendian and dtype.itemsize > 1:
        dtype = dtype.newbyteorder('>')
    row_bytes = msg.width * channels * dtype.itemsize
    if msg.height == 0 or msg.width == 0:
        raise InputError('empty image (width or height is 0)')
    if msg.step < row_bytes or len(msg.data) < msg.step * msg.height:
        raise InputError(f'image data too short: {len(msg.data)} bytes for '
                         f'{msg.width}x{msg.height} {enc} with step {msg.step}')
    buf = np.frombuffer(bytes(msg.data) if not isinstance(msg.data, (bytes, bytearray))
                        else msg.data, dtype=np.uint8, count=msg.step * msg.height)
    rows = buf.reshape(msg.height, msg.step)[:, :row_bytes]
    arr = np.ascontiguousarray(rows).view(dtype).reshape(msg.height, msg.width, channels)
    arr = arr.astype(dtype.newbyteorder('='), copy=False)
    if channels == 1:
        arr = arr[:, :, 0]
    return convert_color(arr, enc, want) if want else arr


def convert_color(arr, have, want):
    """Convert between ``rgb8``, ``bgr8`` and ``mono8`` arrays."""
    import cv2

    if have == want or want is None:
        return arr
    if want == 'mono8':
        if have == 'rgb8':
            return cv2.cvtColor(arr, cv2.COLOR_RGB2GRAY)
        if have == 'bgr8':
            return cv2.cvtColor(arr, cv2.COLOR_BGR2GRAY)
        if have == 'mono16':
            return (arr >> 8).astype(np.uint8)
    if want in ('bgr8', 'rgb8'):
        if have in ('mono8', 'mono16'):
            grey = arr if have == 'mono8' else (arr >> 8).astype(np.uint8)
            return cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        return np.ascontiguousarray(arr[:, :, ::-1])
    raise InputError(f'cannot convert {have} to {want}')


def array_to_image_msg(arr, encoding, image_type, header=None):
    """Build a ``image_type()`` (sensor_msgs/Image) holding ``arr`` with ``encoding``."""
    arr = np.ascontiguousarray(arr)
    if encoding not in _CHANNELS:
        raise InputError(f'unsupported image encoding {encoding!r}')
    channels = _CHANNELS[encoding]
    wrong_colour = channels == 3 and (arr.ndim != 3 or arr.shape[2] != 3)
    if (channels == 1 and arr.ndim != 2) or wrong_colour:
        raise InputError(f'array of shape {arr.shape} does not fit encoding {encoding}')
    if arr.dtype != np.dtype(_DTYPES[encoding]):
        raise InputError(f'array of type {arr.dtype} does not fit encoding {encoding} '
                         f'({np.dtype(_DTYPES[encoding])})')
    msg = image_type()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(arr.shape[0]), int(arr.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(arr.strides[0])
    msg.data = arr.tobytes()
    return msg
