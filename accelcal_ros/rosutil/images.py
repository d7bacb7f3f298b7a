"""
sensor_msgs/Image <-> numpy arrays: the part of cv_bridge this package needs (no rclpy).

Encodings read (what raw cameras publish): ``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``,
``mono8``, ``mono16``, ``bayer_rggb8``/``bggr8``/``gbrg8``/``grbg8`` and their 16-bit
variants, ``yuv422`` (UYVY) and ``yuv422_yuy2`` (YUYV), plus ``8UC1``/``8UC3`` as
mono8/bgr8. Arrays are OpenCV-ordered: HxW (one channel), HxWx3 (BGR or RGB as the
encoding says), HxWx4, HxWx2 (YUV 4:2:2). ``want`` (``bgr8``, ``rgb8`` or ``mono8``)
converts with OpenCV's ``cvtColor`` (demosaicing and YUV as cv_bridge does; 16-bit
data is scaled to 8 bits by dropping the low byte). Row padding (``step`` larger than
``width * channels``) and big-endian 16-bit data are handled. Anything else raises
:class:`~accelcal_ros.errors.InputError` with the topic, the encoding and the sizes.

:func:`image_from_cdr` reads a *serialized* sensor_msgs/Image (what a subscription
created with ``raw=True`` delivers) and returns numpy **views** on that buffer: no
deserialisation, no copy of the pixels unless a conversion is asked for.
:func:`image_cdr` builds the serialized message around an array (``publisher.publish``
accepts these bytes), with one copy of the pixels.
"""
from dataclasses import dataclass
import struct
from typing import Any, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
import numpy as np

# encoding: (channels, dtype)
_LAYOUT = {
    'rgb8': (3, np.uint8), 'bgr8': (3, np.uint8), '8uc3': (3, np.uint8),
    'rgba8': (4, np.uint8), 'bgra8': (4, np.uint8),
    'mono8': (1, np.uint8), '8uc1': (1, np.uint8), 'mono16': (1, np.uint16),
    'bayer_rggb8': (1, np.uint8), 'bayer_bggr8': (1, np.uint8),
    'bayer_gbrg8': (1, np.uint8), 'bayer_grbg8': (1, np.uint8),
    'bayer_rggb16': (1, np.uint16), 'bayer_bggr16': (1, np.uint16),
    'bayer_gbrg16': (1, np.uint16), 'bayer_grbg16': (1, np.uint16),
    'yuv422': (2, np.uint8), 'uyvy': (2, np.uint8), 'yuv422_yuy2': (2, np.uint8),
    'yuyv': (2, np.uint8),
}
SUPPORTED_ENCODINGS = tuple(_LAYOUT)
"""Every encoding :func:`image_msg_to_array` reads (lower case)."""

# OpenCV names a Bayer pattern by the second row's first two pixels (as cv_bridge maps).
_BAYER = {'rggb': 'BayerBG', 'bggr': 'BayerRG', 'gbrg': 'BayerGR', 'grbg': 'BayerGB'}
_OUTPUTS = ('bgr8', 'rgb8', 'mono8')


def _cv_code(name: str) -> int:
    import cv2

    return getattr(cv2, 'COLOR_' + name)


def _canonical(enc: str) -> str:
    return {'8uc3': 'bgr8', '8uc1': 'mono8', 'uyvy': 'yuv422', 'yuyv': 'yuv422_yuy2'}.get(
        enc, enc)


def convert_color(arr: np.ndarray, have: str, want: Optional[str]) -> np.ndarray:
    """
    Convert an array of encoding ``have`` to ``want`` (``bgr8``, ``rgb8`` or ``mono8``).

    Returns ``arr`` itself when nothing changes. 16-bit inputs keep their high byte.
    """
    import cv2

    have = _canonical(have.lower())
    if want is None or have == want:
        return arr
    if want not in _OUTPUTS:
        raise InputError(f'cannot convert {have} to {want}: the targets are '
                         f'{", ".join(_OUTPUTS)}')
    if arr.dtype == np.uint16:
        arr = (arr >> 8).astype(np.uint8)
        have = have.replace('16', '8')
    colour = 'RGB' if want == 'rgb8' else 'BGR'
    target = 'GRAY' if want == 'mono8' else colour
    if have == 'mono8':
        return cv2.cvtColor(arr, _cv_code(f'GRAY2{colour}')) if target != 'GRAY' else arr
    if have in ('rgb8', 'bgr8'):
        if target == 'GRAY':
            return cv2.cvtColor(arr, _cv_code(f'{have[:3].upper()}2GRAY'))
        return np.ascontiguousarray(arr[:, :, ::-1])
    if have in ('rgba8', 'bgra8'):
        return cv2.cvtColor(arr, _cv_code(f'{have[:4].upper()}2{target}'))
    if have.startswith('bayer_'):
        return cv2.cvtColor(arr, _cv_code(f'{_BAYER[have[6:10]]}2{target}'))
    if have in ('yuv422', 'yuv422_yuy2'):
        packing = 'UYVY' if have == 'yuv422' else 'YUY2'
        return cv2.cvtColor(arr, _cv_code(f'YUV2{target}_{packing}'))
    raise InputError(f'cannot convert {have} to {want}')


def _where(topic: str) -> str:
    return f'image on {topic}: ' if topic else ''


def image_array(height: int, width: int, encoding: str, is_bigendian: bool, step: int,
                data: Any, offset: int = 0, want: Optional[str] = None,
                encodings: Sequence[str] = SUPPORTED_ENCODINGS, topic: str = '',
                expected_size: Optional[Tuple[int, int]] = None,
                length: Optional[int] = None) -> np.ndarray:
    """
    Array of an image's fields (``data``: any buffer; pixels start at ``offset``).

    A view on ``data`` where no conversion is needed (padded rows: a strided view);
    ``expected_size`` ``(width, height)`` is checked. ``length``: the message's own
    count of data bytes (default: what ``data`` holds after ``offset``), which must be
    ``step * height`` as sensor_msgs/Image says: more data than the header accounts for
    means the header does not describe it (a wrong width, height or step), so it is
    refused as less is. Raises :class:`InputError` naming ``topic``, the encoding and
    the sizes.
    """
    enc = encoding.lower()
    if enc not in encodings:
        raise InputError(f'{_where(topic)}unsupported image encoding {encoding!r}; '
                         f'supported: {", ".join(encodings)}')
    if expected_size is not None and (width, height) != tuple(expected_size):
        raise InputError(f'{_where(topic)}{encoding} image is {width}x{height}, expected '
                         f'{expected_size[0]}x{expected_size[1]}')
    if height == 0 or width == 0:
        raise InputError(f'{_where(topic)}empty image (width or height is 0)')
    channels, dtype = _LAYOUT[enc]
    dtype = np.dtype(dtype)
    if is_bigendian and dtype.itemsize > 1:
        dtype = dtype.newbyteorder('>')
    row_bytes = width * channels * dtype.itemsize
    size = len(data) - offset if not isinstance(data, np.ndarray) else data.nbytes - offset
    if step < row_bytes:
        raise InputError(f'{_where(topic)}image step {step} is less than a row of '
                         f'{width}x{height} {encoding} ({row_bytes} bytes)')
    length = size if length is None else min(int(length), size)
    if length != step * height:
        which = 'short' if length < step * height else 'long'
        raise InputError(f'{_where(topic)}image data too {which}: {length} bytes for '
                         f'{width}x{height} {encoding} with step {step} (expected '
                         f'{step * height} bytes)')
    buf = np.frombuffer(data, dtype=np.uint8, count=step * height, offset=offset)
    rows = buf.reshape(height, step)[:, :row_bytes]
    if dtype.itemsize > 1 and step % dtype.itemsize:
        rows = np.ascontiguousarray(rows)
    arr = rows.view(dtype).reshape(height, width, channels)
    if dtype.byteorder == '>':
        arr = arr.astype(dtype.newbyteorder('='))
    if channels == 1:
        arr = arr[:, :, 0]
    return convert_color(arr, enc, want) if want else arr


def image_msg_to_array(msg: Any, want: Optional[str] = None,
                       encodings: Sequence[str] = SUPPORTED_ENCODINGS, topic: str = '',
                       expected_size: Optional[Tuple[int, int]] = None) -> np.ndarray:
    """Array of a sensor_msgs/Image (see :func:`image_array`; ``want`` converts)."""
    data = msg.data
    if not isinstance(data, (bytes, bytearray, memoryview, np.ndarray)):
        data = memoryview(data)  # array.array: no copy
    return image_array(msg.height, msg.width, msg.encoding, msg.is_bigendian, msg.step,
                       data, want=want, encodings=encodings, topic=topic,
                       expected_size=expected_size)


@dataclass
class RawImage:
    """The fields of a serialized sensor_msgs/Image; pixels at ``data[offset:]``."""

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    height: int
    width: int
    encoding: str
    is_bigendian: bool
    step: int
    data: Any
    offset: int
    length: int
    """The message's count of data bytes (from ``offset``)."""

    @property
    def stamp_s(self) -> float:
        """Header stamp in seconds."""
        return self.stamp_sec + self.stamp_nanosec * 1e-9


def parse_image_cdr(data: bytes) -> RawImage:
    """
    Read the fields of a serialized (CDR) sensor_msgs/Image without copying the pixels.

    Raises :class:`InputError` if the buffer is not one.
    """
    try:
        order = '<' if data[1] & 1 else '>'
        pos = 4

        def align(n):
            nonlocal pos
            pos += (-(pos - 4)) % n

        def u32():
            nonlocal pos
            align(4)
            (value,) = struct.unpack_from(order + 'I', data, pos)
            pos += 4
            return value

        def text():
            nonlocal pos
            length = u32()
            value = bytes(data[pos:pos + length]).split(b'\0', 1)[0].decode('utf-8')
            pos += length
            return value

        sec, nanosec = struct.unpack_from(order + 'iI', data, pos)
        pos += 8
        frame_id = text()
        height, width = u32(), u32()
        encoding = text()
        is_bigendian = bool(data[pos])
        pos += 1
        step = u32()
        length = u32()
    except (IndexError, struct.error, UnicodeDecodeError) as exc:
        raise InputError(f'not a serialized sensor_msgs/Image ({exc})') from None
    if pos + length > len(data):
        raise InputError(f'serialized sensor_msgs/Image cut short: {len(data) - pos} of '
                         f'{length} data bytes')
    return RawImage(sec, nanosec, frame_id, height, width, encoding, is_bigendian, step,
                    data, pos, length)


def image_from_cdr(data: bytes, want: Optional[str] = None, topic: str = '',
                   expected_size: Optional[Tuple[int, int]] = None
                   ) -> Tuple[RawImage, np.ndarray]:
    """Return the fields and the array (a view unless ``want`` converts) of a raw Image."""
    raw = parse_image_cdr(data)
    arr = image_array(raw.height, raw.width, raw.encoding, raw.is_bigendian, raw.step,
                      raw.data, raw.offset, want=want, topic=topic,
                      expected_size=expected_size, length=raw.length)
    return raw, arr


def _check_output(arr: np.ndarray, encoding: str) -> int:
    if encoding not in _OUTPUTS and encoding != 'mono16':
        raise InputError(f'unsupported image encoding {encoding!r} for output; use '
                         f'{", ".join(_OUTPUTS)} or mono16')
    channels, dtype = _LAYOUT[encoding]
    wrong_colour = channels == 3 and (arr.ndim != 3 or arr.shape[2] != 3)
    if (channels == 1 and arr.ndim != 2) or wrong_colour:
        raise InputError(f'array of shape {arr.shape} does not fit encoding {encoding}')
    if arr.dtype != np.dtype(dtype):
        raise InputError(f'array of type {arr.dtype} does not fit encoding {encoding} '
                         f'({np.dtype(dtype)})')
    return channels


def array_to_image_msg(arr: np.ndarray, encoding: str, image_type: Any,
                       header: Any = None) -> Any:
    """Build a ``image_type()`` (sensor_msgs/Image) holding ``arr`` with ``encoding``."""
    arr = np.ascontiguousarray(arr)
    _check_output(arr, encoding)
    msg = image_type()
    if header is not None:
        msg.header = header
    msg.height, msg.width = int(arr.shape[0]), int(arr.shape[1])
    msg.encoding = encoding
    msg.is_bigendian = 0
    msg.step = int(arr.strides[0])
    msg.data = arr.tobytes()
    return msg


def _cdr_string(value: str, pos: int) -> Tuple[bytes, int]:
    """Aligned CDR string at ``pos`` (bytes from the encapsulation's end)."""
    raw = value.encode('utf-8') + b'\0'
    pad = b'\0' * ((-pos) % 4)
    out = pad + struct.pack('<I', len(raw)) + raw
    return out, pos + len(out)


def image_cdr(arr: np.ndarray, encoding: str, stamp_sec: int, stamp_nanosec: int,
              frame_id: str) -> bytes:
    """
    Serialize a sensor_msgs/Image (CDR, little endian) holding ``arr``: one copy.

    ``publisher.publish(bytes)`` sends it as it is (no message object, no conversion of
    the pixels to a Python sequence).
    """
    arr = np.asarray(arr)
    _check_output(arr, encoding)
    height, width = int(arr.shape[0]), int(arr.shape[1])
    step = width * arr.itemsize * (arr.shape[2] if arr.ndim == 3 else 1)
    head = struct.pack('<iI', int(stamp_sec), int(stamp_nanosec))
    frame, pos = _cdr_string(frame_id, 8)
    sizes = b'\0' * ((-pos) % 4) + struct.pack('<II', height, width)
    pos += len(sizes)
    enc, pos = _cdr_string(encoding, pos)
    flag = b'\0'
    pos += 1
    tail = b'\0' * ((-pos) % 4) + struct.pack('<II', step, height * step)
    prefix = b'\x00\x01\x00\x00' + head + frame + sizes + enc + flag + tail
    pixels = memoryview(np.ascontiguousarray(arr)).cast('B')
    return b''.join((prefix, pixels))
