"""sensor_msgs/Image <-> numpy (the cv_bridge equivalent in accelcal_ros.rosutil.images)."""
from accelcal_ros.errors import InputError
from accelcal_ros.rosutil.images import array_to_image_msg, convert_color, image_msg_to_array
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
    (Image(height=2, width=2, encoding='bgr8', step=5, data=bytes(12)), 'too short'),
    (Image(height=0, width=2, encoding='mono8', step=2, data=b''), 'empty'),
])
def test_bad_messages_raise_input_error_naming_the_problem(msg, words):
    """Unknown encodings are named; truncated and empty data are reported."""
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
