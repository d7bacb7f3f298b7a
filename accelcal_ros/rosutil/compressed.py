"""
sensor_msgs/CompressedImage -> numpy arrays, as image_transport's compressed plugin sends.

The plugin (image_transport_plugins/compressed_image_transport) publishes on
``<base topic>/compressed`` a JPEG or PNG of the image and says what it did in ``format``:
``"<encoding of the original>; <jpeg|png> compressed <target>"``, e.g.
``"bgr8; jpeg compressed bgr8"``, ``"rgb8; png compressed bgr8"``,
``"mono8; jpeg compressed mono8"`` or, from older publishers, ``"mono8; png compressed"``;
camera drivers that encode on the device often write only ``"jpeg"`` or ``"png"``.
:func:`parse_format` reads that; :func:`decode_compressed` decodes the data with OpenCV
(``cv2.imdecode``, which releases the GIL: several decodes run in parallel in threads)
following the plugin's subscriber:

* colour originals whose target starts with ``bgr`` hold BGR data; a colour original
  without a ``bgr`` target holds RGB data; a format without ``;`` (the legacy form) holds
  what OpenCV decodes: BGR for three channels, mono for one;
* 16-bit data (PNG) keeps its high byte, as :func:`~.images.convert_color` does;
* ``want`` (``bgr8``, ``rgb8`` or ``mono8``) converts, Bayer originals are demosaiced.

Bad input raises :class:`~accelcal_ros.errors.InputError` with one line, before any
large allocation where the header allows: a ``format`` that is no image format of the
plugin (``compressedDepth``, ``h264``, ``qoi``, ...), data that is not what the format
says, a JPEG cut short (no end-of-image marker) or a PNG without its ``IEND`` chunk,
a size other than ``expected_size`` (read from the JPEG/PNG header, before decoding),
and data that OpenCV cannot decode.

:func:`parse_compressed_cdr` reads a *serialized* CompressedImage (a ``raw=True``
subscription's bytes) without copying the data; :func:`encode_compressed` writes what
the plugin's publisher writes (tests, benchmarks, simulated cameras).
"""
from dataclasses import dataclass
import struct
from typing import Any, Optional, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.jpeg import encode_jpeg
from accelcal_ros.rosutil.images import convert_color, SUPPORTED_ENCODINGS
import numpy as np

CODECS = ('jpeg', 'png')
"""Compressions of image_transport's ``compressed`` plugin that are decoded here."""

COLOUR_ENCODINGS = ('rgb8', 'bgr8', 'rgba8', 'bgra8', 'rgb16', 'bgr16', 'rgba16', 'bgra16')
"""sensor_msgs image_encodings ``isColor``: the plugin converts these to BGR."""

_JPEG_MAGIC = b'\xff\xd8\xff'
_PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
_PNG_IEND = b'IEND\xaeB`\x82'
_EOI_SEARCH = 64
"""A JPEG's end-of-image marker is looked for in its last bytes (drivers pad a little)."""
# JPEG start-of-frame markers (every SOFn but DHT C4, JPG C8, DAC CC)
_SOF = frozenset(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


@dataclass(frozen=True)
class CompressedFormat:
    """What a ``format`` field says: original encoding ('' legacy), codec, BGR data."""

    encoding: str
    codec: str
    bgr: bool


def _not_image(fmt: str, why: str) -> InputError:
    return InputError(f'format {fmt!r} is not an image format of the compressed transport '
                      f'({why}); expected e.g. "bgr8; jpeg compressed bgr8", '
                      '"mono8; png compressed mono8", "jpeg" or "png"')


def parse_format(fmt: str) -> CompressedFormat:
    """
    Read a CompressedImage ``format`` as image_transport's compressed subscriber does.

    ``codec`` is ``'jpeg'``, ``'png'`` or ``''`` (legacy form without a codec: found
    from the data's magic bytes); ``bgr`` tells the channel order of 3-channel data.
    """
    text = fmt.strip()
    if ';' not in text:
        word = text.lower()
        if word not in ('', 'jpeg', 'jpg', 'png'):
            raise _not_image(fmt, 'no "<encoding>; <codec> compressed" and no codec name')
        return CompressedFormat('', 'jpeg' if word == 'jpg' else word, True)
    encoding, rest = (part.strip() for part in text.split(';', 1))
    words = rest.lower().split()
    if len(words) < 2 or words[1] != 'compressed' or words[0] not in CODECS:
        what = rest.split()[0] if words else 'nothing'
        raise _not_image(fmt, f'{what!r} after the encoding; decoded here: '
                         f'{" or ".join(c + " compressed" for c in CODECS)}')
    encoding = encoding.lower()
    if not encoding:
        raise _not_image(fmt, 'no encoding before ";"')
    target = words[2] if len(words) > 2 else ''
    bgr = target.startswith('bgr') or encoding not in COLOUR_ENCODINGS
    return CompressedFormat(encoding, words[0], bgr)


def _u16(data: Any, pos: int) -> int:
    return (int(data[pos]) << 8) | int(data[pos + 1])


def jpeg_size(data: Any) -> Optional[Tuple[int, int]]:
    """Return ``(width, height)`` from a JPEG's start-of-frame header; None if there is none."""
    pos, size = 2, len(data)
    while pos + 4 <= size:
        if data[pos] != 0xFF:
            return None
        marker = data[pos + 1]
        if marker == 0xFF:                          # fill byte
            pos += 1
            continue
        if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:
            pos += 2
            continue
        if marker in (0xD9, 0xDA):                  # end of image / scan before a frame
            return None
        length = _u16(data, pos + 2)
        if marker in _SOF:
            if pos + 9 > size or length < 8:
                return None
            return _u16(data, pos + 7), _u16(data, pos + 5)
        pos += 2 + length
    return None


def png_size(data: Any) -> Optional[Tuple[int, int]]:
    """Return ``(width, height)`` from a PNG's IHDR chunk; None if it is not there."""
    if len(data) < 24 or bytes(data[12:16]) != b'IHDR':
        return None
    width, height = struct.unpack('>II', bytes(data[16:24]))
    return int(width), int(height)


def _label(arr: np.ndarray, info: CompressedFormat) -> str:
    """Name the encoding of a decoded 8-bit array (the format, OpenCV's channel order)."""
    channels = 1 if arr.ndim == 2 else arr.shape[2]
    if channels == 1:
        own = info.encoding.replace('16', '8')
        return own if own in SUPPORTED_ENCODINGS and own not in COLOUR_ENCODINGS \
            and 'yuv' not in own and own != '8uc3' else 'mono8'
    order = 'bgr' if info.bgr else 'rgb'
    return order + ('8' if channels == 3 else 'a8')


def decode_compressed(data: Any, fmt: str, want: Optional[str] = None, topic: str = '',
                      expected_size: Optional[Tuple[int, int]] = None
                      ) -> Tuple[np.ndarray, str]:
    """
    Decode CompressedImage ``data`` (any buffer) whose ``format`` is ``fmt``.

    Returns ``(array, encoding)``: 8-bit, OpenCV-ordered (HxW or HxWx3/4), ``encoding``
    ``want`` when given, else what the data holds (``bgr8``, ``rgb8``, ``mono8``, a
    Bayer pattern, ...). ``expected_size`` ``(width, height)`` is checked against the
    header before decoding. Raises :class:`InputError` (see the module).
    """
    import cv2

    where = f'compressed image on {topic}: ' if topic else 'compressed image: '
    info = parse_format(fmt)
    buf = np.frombuffer(data, dtype=np.uint8)
    if buf.size == 0:
        raise InputError(f'{where}no data')
    codec = info.codec
    if not codec:
        codec = 'jpeg' if buf[:3].tobytes() == _JPEG_MAGIC else \
            'png' if buf[:8].tobytes() == _PNG_MAGIC else ''
        if not codec:
            raise InputError(f'{where}data is neither JPEG nor PNG (format {fmt!r})')
    name = codec.upper()
    if codec == 'jpeg':
        if buf[:3].tobytes() != _JPEG_MAGIC:
            raise InputError(f'{where}data is not a JPEG (format {fmt!r})')
        if buf[-_EOI_SEARCH:].tobytes().rfind(b'\xff\xd9') < 0:
            raise InputError(f'{where}JPEG cut short (no end-of-image marker)')
        size = jpeg_size(buf)
    else:
        if buf[:8].tobytes() != _PNG_MAGIC:
            raise InputError(f'{where}data is not a PNG (format {fmt!r})')
        if buf[-8:].tobytes() != _PNG_IEND:
            raise InputError(f'{where}PNG cut short (no IEND chunk)')
        size = png_size(buf)
    if size is None or min(size) == 0:
        raise InputError(f'{where}corrupt {name} header (no image size)')
    if expected_size is not None and tuple(size) != tuple(expected_size):
        raise InputError(f'{where}{name} image is {size[0]}x{size[1]}, expected '
                         f'{expected_size[0]}x{expected_size[1]}')
    arr = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
    if arr is None or arr.size == 0:
        raise InputError(f'{where}{name} data does not decode (corrupt)')
    if (arr.shape[1], arr.shape[0]) != tuple(size):
        raise InputError(f'{where}{name} decodes to {arr.shape[1]}x{arr.shape[0]}, its '
                         f'header says {size[0]}x{size[1]} (corrupt)')
    if arr.dtype == np.uint16:
        arr = (arr >> 8).astype(np.uint8)
    elif arr.dtype != np.uint8:
        raise InputError(f'{where}{name} of {arr.dtype} samples; 8 or 16 bits expected')
    if arr.ndim == 3 and arr.shape[2] not in (3, 4):
        raise InputError(f'{where}{name} of {arr.shape[2]} channels; 1, 3 or 4 expected')
    label = _label(arr, info)
    if want is None or want == label:
        return arr, label
    return convert_color(arr, label, want), want


@dataclass
class RawCompressed:
    """The fields of a serialized sensor_msgs/CompressedImage; data at ``data[offset:end]``."""

    stamp_sec: int
    stamp_nanosec: int
    frame_id: str
    format: str  # noqa: A003 - the message field's name
    data: Any
    offset: int
    end: int

    @property
    def stamp_s(self) -> float:
        """Header stamp in seconds."""
        return self.stamp_sec + self.stamp_nanosec * 1e-9

    def payload(self) -> memoryview:
        """Return the compressed bytes (a view, no copy)."""
        return memoryview(self.data)[self.offset:self.end]


def parse_compressed_cdr(data: Any) -> RawCompressed:
    """
    Read the fields of a serialized (CDR) CompressedImage without copying the data.

    Raises :class:`InputError` if the buffer is not one.
    """
    try:
        order = '<' if data[1] & 1 else '>'
        sec, nanosec = struct.unpack_from(order + 'iI', data, 4)
        pos = 12
        texts = []
        for _ in range(2):                           # header.frame_id, format
            pos += (-(pos - 4)) % 4
            (length,) = struct.unpack_from(order + 'I', data, pos)
            pos += 4
            texts.append(bytes(data[pos:pos + length]).split(b'\0', 1)[0].decode('utf-8'))
            pos += length
        pos += (-(pos - 4)) % 4
        (length,) = struct.unpack_from(order + 'I', data, pos)
        pos += 4
    except (IndexError, TypeError, struct.error, UnicodeDecodeError) as exc:
        raise InputError(f'not a serialized sensor_msgs/CompressedImage ({exc})') from None
    if pos + length > len(data):
        raise InputError(f'serialized sensor_msgs/CompressedImage cut short: '
                         f'{len(data) - pos} of {length} data bytes')
    return RawCompressed(sec, nanosec, texts[0], texts[1], data, pos, pos + length)


def encode_compressed(arr: np.ndarray, encoding: str, codec: str = 'jpeg',
                      quality: int = 90, png_level: int = 3) -> Tuple[str, bytes]:
    """
    Return ``(format, data)`` as image_transport's compressed publisher writes them.

    ``arr`` in ``encoding`` (``bgr8``, ``rgb8`` or ``mono8``): colour is converted to
    BGR (``"rgb8; jpeg compressed bgr8"``), mono stays mono (``"mono8; png compressed
    mono8"``).
    """
    import cv2

    if codec not in CODECS:
        raise InputError(f'codec {codec!r}: use {" or ".join(CODECS)}')
    colour = encoding in COLOUR_ENCODINGS
    target = 'bgr8' if colour else encoding
    image = convert_color(arr, encoding, 'bgr8') if colour else arr
    if codec == 'jpeg':
        return f'{encoding}; {codec} compressed {target}', encode_jpeg(image, quality)
    ok, data = cv2.imencode('.png', image, [cv2.IMWRITE_PNG_COMPRESSION, int(png_level)])
    if not ok:
        raise InputError(f'{codec} encoding of a {encoding} image failed')
    return f'{encoding}; {codec} compressed {target}', data.tobytes()
