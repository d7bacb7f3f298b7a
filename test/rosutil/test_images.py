"""sensor_msgs/Image <-> numpy (the cv_bridge equivalent in accelcal_ros.rosutil.images)."""
from accelcal_ros.errors import InputError
from accelcal_ros.rosutil.images import (array_to_image_msg, convert_color, image_cdr,
                                         image_from_cdr, image_msg_to_array, parse_image_cdr)
import numpy as np
import pytest
from sensor_msgs.msg import Image
from std_msgs.msg import Header


def _colour(h=5, w=7):
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)


@pytest.mark.parametrize('encoding', ['rgb8', 'bgr8', 'mono8'])
def test_round_trip_keeps_pixels_and_header(encoding):
    """Convert array -> msg -> array without change; header, size and step are set."""
    arr = _colour() if encoding != 'mono8' else _colour()[:, :, 0].copy()
    header = Header(frame_id='cam')
    header.stamp.sec = 12
    msg = array_to_image_msg(arr, encoding, Image, header)
    assert (msg.width, msg.height, msg.encoding, msg.is_bigendian) == (7, 5, encoding, 0)
    assert msg.step == arr.strides[0] and msg.header.frame_id == 'cam'
    assert msg.header.stamp.sec == 12
    back = image_msg_to_array(msg)
    assert back.dtype == np.uint8 and np.array_equal(back, arr)


def test_colour_order_conversions():
    """rgb8 is reversed to BGR on request; grey conversions use OpenCV's weights."""
    bgr = _colour()
    rgb_msg = array_to_image_msg(np.ascontiguousarray(bgr[:, :, ::-1]), 'rgb8', Image)
    assert np.array_equal(image_msg_to_array(rgb_msg, want='bgr8'), bgr)
    bgr_msg = array_to_image_msg(bgr, 'bgr8', Image)
    assert np.array_equal(image_msg_to_array(bgr_msg, want='rgb8'), bgr[:, :, ::-1])
    grey_from_rgb = image_msg_to_array(rgb_msg, want='mono8')
    grey_from_bgr = image_msg_to_array(bgr_msg, want='mono8')
    assert grey_from_rgb.shape == (5, 7) and np.array_equal(grey_from_rgb, grey_from_bgr)
    expected = np.rint(0.114 * bgr[..., 0] + 0.587 * bgr[..., 1] + 0.299 * bgr[..., 2])
    assert np.abs(grey_from_bgr.astype(int) - expected).max() <= 1
    mono_msg = array_to_image_msg(grey_from_bgr, 'mono8', Image)
    expanded = image_msg_to_array(mono_msg, want='bgr8')
    assert expanded.shape == (5, 7, 3) and np.all(expanded[..., 1] == grey_from_bgr)


def test_row_padding_is_skipped():
    """A step larger than width * channels (padded rows) is handled."""
    arr = _colour(4, 3)
    msg = Image(height=4, width=3, encoding='bgr8', step=12)
    padded = np.zeros((4, 12), np.uint8)
    padded[:, :9] = arr.reshape(4, 9)
    padded[:, 9:] = 255
    msg.data = padded.tobytes()
    assert np.array_equal(image_msg_to_array(msg), arr)


def test_mono16_big_endian_reads_when_allowed():
    """mono16 (not a stitcher input) reads correctly, including big-endian data."""
    values = np.array([[1, 256], [65535, 4660]], dtype='>u2')
    msg = Image(height=2, width=2, encoding='mono16', step=4, is_bigendian=1)
    msg.data = values.tobytes()
    arr = image_msg_to_array(msg, encodings=('mono16',))
    assert arr.dtype == np.uint16 and arr.tolist() == [[1, 256], [65535, 4660]]
    assert convert_color(arr, 'mono16', 'mono8').tolist() == [[0, 1], [255, 18]]


@pytest.mark.parametrize('msg, words', [
    (Image(height=2, width=2, encoding='16UC1', step=4, data=bytes(8)), "'16UC1'"),
    (Image(height=2, width=2, encoding='rgba4', step=8, data=bytes(16)), "'rgba4'.*rgb8"),
    (Image(height=2, width=2, encoding='bgr8', step=6, data=bytes(11)), 'too short'),
    (Image(height=2, width=2, encoding='bgr8', step=5, data=bytes(12)),
     'step 5 is less than a row'),
    (Image(height=2, width=2, encoding='bgr8', step=6, data=bytes(13)), 'too long: 13 bytes'),
    (Image(height=2, width=2, encoding='bgr8', step=6, data=bytes(24)), 'too long'),
    (Image(height=0, width=2, encoding='mono8', step=2, data=b''), 'empty'),
])
def test_bad_messages_raise_input_error_naming_the_problem(msg, words):
    """Unknown encodings are named; truncated, over-long and empty data are reported."""
    with pytest.raises(InputError, match=words):
        image_msg_to_array(msg)


def test_array_to_msg_rejects_mismatched_shapes():
    """A colour array cannot be sent as mono8 and vice versa; unknown encodings fail."""
    with pytest.raises(InputError, match='does not fit'):
        array_to_image_msg(_colour(), 'mono8', Image)
    with pytest.raises(InputError, match='does not fit'):
        array_to_image_msg(np.zeros((3, 3), np.uint8), 'bgr8', Image)
    with pytest.raises(InputError, match='unsupported'):
        array_to_image_msg(np.zeros((3, 3, 2), np.uint8), 'yuv422', Image)
    with pytest.raises(InputError, match='cannot convert'):
        convert_color(np.zeros((2, 2), np.uint8), 'mono8', 'yuv422')
    with pytest.raises(InputError, match='type float64'):
        array_to_image_msg(np.zeros((3, 3)), 'mono8', Image)


# -- encodings raw cameras publish (issue 15 part 3) ----------------------------------------
BGR = (20, 120, 220)
_PATTERNS = {'rggb': ('R', 'G', 'G', 'B'), 'bggr': ('B', 'G', 'G', 'R'),
             'gbrg': ('G', 'B', 'R', 'G'), 'grbg': ('G', 'R', 'B', 'G')}


def _bayer(pattern, height=8, width=10, scale=1, dtype=np.uint8):
    """Bayer mosaic of a uniform BGR colour: pattern = top-left 2x2, row-major."""
    value = {'B': BGR[0], 'G': BGR[1], 'R': BGR[2]}
    raw = np.zeros((height, width), dtype)
    for k, colour in enumerate(_PATTERNS[pattern]):
        raw[k // 2::2, k % 2::2] = value[colour] * scale
    return raw


@pytest.mark.parametrize('pattern', sorted(_PATTERNS))
@pytest.mark.parametrize('bits', [8, 16])
def test_bayer_encodings_demosaic_to_the_known_colour(pattern, bits):
    """Each Bayer pattern (8 and 16 bit) gives back the uniform colour it was made of."""
    raw = _bayer(pattern, scale=257 if bits == 16 else 1,
                 dtype=np.uint16 if bits == 16 else np.uint8)
    msg = Image(height=8, width=10, encoding=f'bayer_{pattern}{bits}', step=10 * bits // 8)
    msg.data = raw.tobytes()
    bgr = image_msg_to_array(msg, want='bgr8')
    assert bgr.shape == (8, 10, 3)
    assert np.abs(bgr[2:-2, 2:-2].astype(int) - BGR).max() <= 1, bgr[4, 4]
    rgb = image_msg_to_array(msg, want='rgb8')
    assert np.array_equal(rgb, bgr[:, :, ::-1])
    grey = image_msg_to_array(msg, want='mono8')
    expected = 0.114 * BGR[0] + 0.587 * BGR[1] + 0.299 * BGR[2]
    assert abs(int(grey[4, 4]) - expected) <= 1.5


def _yuv_to_bgr(y, u, v):
    """BT.601 video range, as OpenCV's YUV 4:2:2 conversions (and cv_bridge)."""
    c, d, e = 1.164 * (y - 16), u - 128, v - 128
    return np.clip([c + 2.018 * d, c - 0.391 * d - 0.813 * e, c + 1.596 * e], 0, 255)


@pytest.mark.parametrize('encoding, order', [('yuv422', 'UYVY'), ('uyvy', 'UYVY'),
                                             ('yuv422_yuy2', 'YUYV'), ('yuyv', 'YUYV')])
def test_yuv422_encodings_give_the_known_colour(encoding, order):
    """UYVY (yuv422) and YUYV (yuv422_yuy2) pixel pairs decode to the BT.601 colour."""
    y, u, v = 100, 150, 90
    pair = {'UYVY': [u, y, v, y], 'YUYV': [y, u, y, v]}[order]
    data = np.tile(np.array(pair, np.uint8), 4 * 6 // 2)     # 4 rows of 6 pixels
    msg = Image(height=4, width=6, encoding=encoding, step=12, data=data.tobytes())
    bgr = image_msg_to_array(msg, want='bgr8')
    assert np.abs(bgr.astype(float) - _yuv_to_bgr(y, u, v)).max() <= 2.0, bgr[0, 0]
    assert abs(float(image_msg_to_array(msg, want='mono8')[1, 1]) - 1.164 * (y - 16)) <= 12
    assert image_msg_to_array(msg).shape == (4, 6, 2)         # no conversion asked


@pytest.mark.parametrize('encoding', ['rgba8', 'bgra8'])
def test_four_channel_encodings_drop_alpha(encoding):
    """rgba8/bgra8 lose their alpha channel and keep the colour order asked for."""
    bgr = _colour()
    alpha = np.full(bgr.shape[:2] + (1,), 7, np.uint8)
    four = np.concatenate([bgr if encoding == 'bgra8' else bgr[:, :, ::-1], alpha], axis=2)
    msg = Image(height=5, width=7, encoding=encoding, step=28, data=four.tobytes())
    assert np.array_equal(image_msg_to_array(msg, want='bgr8'), bgr)
    assert np.array_equal(image_msg_to_array(msg, want='rgb8'), bgr[:, :, ::-1])
    assert image_msg_to_array(msg).shape == (5, 7, 4)


def test_mono16_scales_to_eight_bits_for_every_target():
    """mono16 keeps the high byte for mono8 and bgr8 (grey expanded)."""
    values = np.array([[0, 256], [65535, 4660]], dtype=np.uint16)
    msg = Image(height=2, width=2, encoding='mono16', step=4, data=values.tobytes())
    assert image_msg_to_array(msg, want='mono8').tolist() == [[0, 1], [255, 18]]
    assert image_msg_to_array(msg, want='bgr8')[1, 1].tolist() == [18, 18, 18]


def test_wrong_size_or_encoding_names_topic_encoding_and_expected_size():
    """One clear line: the topic, the encoding, what arrived and what was expected."""
    msg = array_to_image_msg(_colour(5, 7), 'bgr8', Image)
    with pytest.raises(InputError, match=r'image on cam0/image_raw: bgr8 image is 7x5, '
                                         r'expected 64x48'):
        image_msg_to_array(msg, topic='cam0/image_raw', expected_size=(64, 48))
    msg.encoding = 'jpeg'
    with pytest.raises(InputError, match='image on cam0/image_raw: unsupported image '
                                         "encoding 'jpeg'; supported: rgb8, bgr8"):
        image_msg_to_array(msg, topic='cam0/image_raw')
    msg = Image(height=4, width=6, encoding='yuv422', step=12, data=bytes(40))
    with pytest.raises(InputError, match='40 bytes for 6x4 yuv422 with step 12 .expected '
                                         '48 bytes'):
        image_msg_to_array(msg, topic='cam1/image_raw')


@pytest.mark.parametrize('frame_id', ['', 'a', 'cam', 'cam_optical'])
def test_serialized_images_are_read_as_views_and_written_in_one_piece(frame_id):
    """image_from_cdr views rclpy's serialized bytes; image_cdr deserialises to the same."""
    from rclpy.serialization import deserialize_message, serialize_message

    arr = _colour(6, 9)
    header = Header(frame_id=frame_id)
    header.stamp.sec, header.stamp.nanosec = 1700000000, 123456789
    data = serialize_message(array_to_image_msg(arr, 'bgr8', Image, header))
    raw, view = image_from_cdr(data)
    assert (raw.stamp_sec, raw.stamp_nanosec, raw.frame_id) == (1700000000, 123456789,
                                                                frame_id)
    assert np.array_equal(view, arr) and np.shares_memory(view, np.frombuffer(data, np.uint8))
    back = deserialize_message(image_cdr(arr, 'bgr8', 1700000000, 123456789, frame_id),
                               Image)
    assert back.header == header and np.array_equal(image_msg_to_array(back), arr)
    with pytest.raises(InputError, match='cut short'):
        parse_image_cdr(data[:-10])
    with pytest.raises(InputError, match='not a serialized sensor_msgs/Image'):
        parse_image_cdr(b'\x00\x01\x00\x00\x01')
    # bytes after the message (CDR padding) are not pixels; a data field longer than
    # step * height is refused: the header does not describe it
    assert np.array_equal(image_from_cdr(data + bytes(3))[1], arr)
    long = array_to_image_msg(arr, 'bgr8', Image, header)
    long.data = bytes(long.data) + bytes(27)
    with pytest.raises(InputError, match='too long'):
        image_from_cdr(serialize_message(long))
