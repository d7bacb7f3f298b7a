"""The one JPEG encoder (accelcal_ros/jpeg.py): both encoders, colour orders, bad input."""
from accelcal_ros.errors import InputError
from accelcal_ros.jpeg import encode_jpeg, encoder, ENCODERS
import cv2
import numpy as np
import pytest

try:
    import simplejpeg  # noqa: F401
    AVAILABLE = ENCODERS
except ImportError:
    AVAILABLE = ('opencv',)


def _image(height=120, width=160):
    y, x = np.mgrid[0:height, 0:width]
    return np.dstack([(x * 1.5) % 255, (y * 2.0) % 255, (x + y) % 255]).astype(np.uint8)


def _decode(data):
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)


def test_the_default_is_the_fastest_installed():
    assert encoder() == AVAILABLE[0]


@pytest.mark.parametrize('use', ENCODERS)
def test_colour_and_grey_read_back(use):
    if use not in AVAILABLE:
        pytest.skip(f'{use} is not installed here')
    bgr = _image()
    back = _decode(encode_jpeg(bgr, 95, use=use))
    assert back.shape == bgr.shape and cv2.PSNR(bgr, back) > 35.0
    # RGB data comes back as the same colours (OpenCV decodes to BGR)
    back_rgb = _decode(encode_jpeg(np.ascontiguousarray(bgr[:, :, ::-1]), 95, rgb=True, use=use))
    assert cv2.PSNR(bgr, back_rgb) > 35.0
    # a red image stays red: the channel order is not swapped
    red = np.zeros((32, 32, 3), np.uint8)
    red[..., 2] = 255
    assert _decode(encode_jpeg(red, 90, use=use))[16, 16].tolist()[2] > 240
    grey = bgr[:, :, 1]
    for arr in (grey, grey[:, :, None], bgr[::2, ::3, 1]):   # views, not contiguous
        back = _decode(encode_jpeg(arr, 95, use=use))
        plane = arr[:, :, 0] if arr.ndim == 3 else arr
        assert back.shape == plane.shape and cv2.PSNR(np.ascontiguousarray(plane), back) > 35.0


def test_the_encoders_write_alike():
    if len(AVAILABLE) < 2:
        pytest.skip('simplejpeg is not installed here: only OpenCV encodes')
    image = _image(480, 640)
    sizes = [len(encode_jpeg(image, 80, use=use)) for use in ENCODERS]
    assert abs(sizes[0] - sizes[1]) <= 0.05 * sizes[1]   # both 4:2:0, the same quality


@pytest.mark.parametrize('image, quality, use, words', [
    (np.zeros((8, 8, 3), np.float32), 80, None, '8-bit'),
    (np.zeros((8, 8, 4), np.uint8), 80, None, '3-channel'),
    (np.zeros((0, 8), np.uint8), 80, None, '8-bit grey'),
    (np.zeros((8, 8), np.uint8), 0, None, 'quality'),
    (np.zeros((8, 8), np.uint8), 101, None, 'quality'),
    (np.zeros((8, 8), np.uint8), 80, 'turbo', 'not available'),
])
def test_bad_input_is_one_clear_reason(image, quality, use, words):
    with pytest.raises(InputError, match=words):
        encode_jpeg(image, quality, use=use)
