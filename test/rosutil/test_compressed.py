"""CompressedImage decoding as image_transport's compressed plugin writes it (rosutil)."""
from accelcal_ros.errors import InputError
from accelcal_ros.rosutil.compressed import (decode_compressed, encode_compressed, jpeg_size,
                                             parse_compressed_cdr, parse_format, png_size)
import cv2
import numpy as np
import pytest
from rclpy.serialization import serialize_message
from sensor_msgs.msg import CompressedImage


def _scene(h=48, w=64):
    """Return a smooth colour image (JPEG keeps it within a few grey levels)."""
    y, x = np.mgrid[0:h, 0:w].astype(float)
    image = np.stack([128 + 100 * np.sin(x / 9.0), 128 + 100 * np.cos(y / 7.0),
                      64 + x + y], axis=2)
    return np.clip(image, 0, 255).astype(np.uint8)


def _png(image):
    return cv2.imencode('.png', image)[1].tobytes()


@pytest.mark.parametrize('fmt, encoding, codec, bgr', [
    ('bgr8; jpeg compressed bgr8', 'bgr8', 'jpeg', True),
    ('rgb8; jpeg compressed bgr8', 'rgb8', 'jpeg', True),
    ('rgb8; png compressed bgr8', 'rgb8', 'png', True),
    ('rgb8; png compressed', 'rgb8', 'png', False),
    ('mono8; jpeg compressed mono8', 'mono8', 'jpeg', True),
    ('mono8; png compressed ', 'mono8', 'png', True),
    ('BGR8;JPEG compressed BGR8', 'bgr8', 'jpeg', True),
    ('jpeg', '', 'jpeg', True), ('png', '', 'png', True), ('', '', '', True),
])
def test_formats_of_the_plugin_are_read(fmt, encoding, codec, bgr):
    """The original encoding, the codec and the channel order of 3-channel data."""
    info = parse_format(fmt)
    assert (info.encoding, info.codec, info.bgr) == (encoding, codec, bgr)


@pytest.mark.parametrize('fmt', ['16UC1; compressedDepth png', 'h264', 'theora',
                                 'bgr8; qoi compressed bgr8', 'bgr8; tiff compressed',
                                 '; jpeg compressed bgr8', 'bgr8;'])
def test_formats_that_are_no_image_format_are_refused(fmt):
    with pytest.raises(InputError, match='not an image format of the compressed transport'):
        parse_format(fmt)


def test_colour_order_follows_the_format():
    """BGR target: data is BGR; colour original without one: data is RGB (as the subscriber)."""
    bgr = _scene()
    rgb = np.ascontiguousarray(bgr[:, :, ::-1])
    data = _png(bgr)                        # OpenCV writes BGR arrays as they are
    arr, enc = decode_compressed(data, 'rgb8; png compressed bgr8')
    assert enc == 'bgr8' and np.array_equal(arr, bgr)
    arr, enc = decode_compressed(data, 'rgb8; png compressed bgr8', want='rgb8')
    assert enc == 'rgb8' and np.array_equal(arr, rgb)
    arr, enc = decode_compressed(data, 'rgb8; png compressed')   # the bytes are R, G, B
    assert enc == 'rgb8' and np.array_equal(arr, bgr)
    arr, enc = decode_compressed(data, 'png')
    assert enc == 'bgr8' and np.array_equal(arr, bgr)
    grey, enc = decode_compressed(data, 'bgr8; png compressed bgr8', want='mono8')
    assert enc == 'mono8' and np.array_equal(grey, cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))


@pytest.mark.parametrize('encoding', ['bgr8', 'rgb8', 'mono8'])
@pytest.mark.parametrize('codec', ['jpeg', 'png'])
def test_encode_then_decode_round_trip(encoding, codec):
    """What encode_compressed writes (the publisher's format) decodes to the image."""
    bgr = _scene()
    image = {'bgr8': bgr, 'rgb8': np.ascontiguousarray(bgr[:, :, ::-1]),
             'mono8': cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY)}[encoding]
    fmt, data = encode_compressed(image, encoding, codec, quality=95)
    target = 'mono8' if encoding == 'mono8' else 'bgr8'
    assert fmt == f'{encoding}; {codec} compressed {target}'
    arr, enc = decode_compressed(data, fmt, want=encoding, expected_size=(64, 48))
    assert enc == encoding and arr.shape == image.shape and arr.dtype == np.uint8
    error = np.abs(arr.astype(int) - image).mean()
    assert error == 0 if codec == 'png' else error < 3.0


def test_sixteen_bit_png_keeps_the_high_byte_and_bayer_is_demosaiced():
    grey16 = (np.arange(48 * 64, dtype=np.uint32).reshape(48, 64) * 21).astype(np.uint16)
    arr, enc = decode_compressed(_png(grey16), 'mono16; png compressed mono16')
    assert enc == 'mono8' and np.array_equal(arr, (grey16 >> 8).astype(np.uint8))
    bayer = _scene()[:, :, 1].copy()
    arr, enc = decode_compressed(_png(bayer), 'bayer_rggb8; png compressed', want='bgr8')
    assert enc == 'bgr8' and np.array_equal(arr, cv2.cvtColor(bayer, cv2.COLOR_BayerBG2BGR))


def test_png_with_alpha_is_converted():
    bgr = _scene()
    bgra = np.dstack([bgr, np.full(bgr.shape[:2], 200, np.uint8)])
    arr, enc = decode_compressed(_png(bgra), 'bgra8; png compressed bgr8', want='bgr8')
    assert enc == 'bgr8' and np.array_equal(arr, bgr)


def test_sizes_are_read_from_the_headers():
    image = _scene(30, 50)
    jpeg = cv2.imencode('.jpg', image)[1]
    assert jpeg_size(jpeg) == (50, 30) and png_size(_png(image)) == (50, 30)
    assert jpeg_size(np.frombuffer(b'\xff\xd8\xff\xd9', np.uint8)) is None


def _jpeg():
    return encode_compressed(_scene(), 'bgr8', 'jpeg')


@pytest.mark.parametrize('case, fragment', [
    ('truncated', 'JPEG cut short'),
    ('corrupt', 'corrupt'),
    ('garbage', 'data is not a JPEG'),
    ('empty', 'no data'),
    ('png_wrong_size', 'PNG image is 64x48, expected 32x24'),
    ('png_truncated', 'PNG cut short'),
    ('png_as_jpeg', 'data is not a JPEG'),
    ('not_image', 'not an image format'),
    ('legacy_garbage', 'neither JPEG nor PNG'),
])
def test_bad_input_is_one_clear_error(case, fragment):
    """Corrupt, truncated, wrong-size or mislabelled data: InputError, never a crash."""
    fmt, jpeg = _jpeg()
    png = _png(_scene())
    expected = (32, 24) if case == 'png_wrong_size' else None
    data, form = {
        'truncated': (jpeg[:len(jpeg) // 2], fmt),
        'corrupt': (jpeg[:20] + bytes(200) + jpeg[220:], fmt),
        'garbage': (bytes(range(256)) * 4, fmt),
        'empty': (b'', fmt),
        'png_wrong_size': (png, 'bgr8; png compressed bgr8'),
        'png_truncated': (png[:len(png) - 30], 'bgr8; png compressed bgr8'),
        'png_as_jpeg': (png, fmt),
        'not_image': (jpeg, '16UC1; compressedDepth png'),
        'legacy_garbage': (b'\x00' * 100, ''),
    }[case]
    with pytest.raises(InputError, match=fragment):
        decode_compressed(data, form, topic='cam0/image_raw/compressed',
                          expected_size=expected)


def test_fuzzed_jpegs_decode_or_raise_input_error():
    """Random byte damage never raises anything but InputError; sizes stay right."""
    fmt, jpeg = _jpeg()
    rng = np.random.default_rng(4)
    outcomes = set()
    for _ in range(60):
        data = bytearray(jpeg)
        for pos in rng.integers(0, len(data), int(rng.integers(1, 20))):
            data[pos] = int(rng.integers(0, 256))
        try:
            arr, _ = decode_compressed(bytes(data), fmt, expected_size=(64, 48))
        except InputError:
            outcomes.add('refused')
            continue
        assert arr.shape == (48, 64, 3)
        outcomes.add('decoded')
    assert 'refused' in outcomes


def test_serialized_message_is_read_without_copying_the_data():
    fmt, jpeg = _jpeg()
    msg = CompressedImage(format=fmt, data=jpeg)
    msg.header.frame_id = 'cam0_optical'
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1700000000, 250000000
    raw = parse_compressed_cdr(serialize_message(msg))
    assert (raw.frame_id, raw.format) == ('cam0_optical', fmt)
    assert raw.stamp_s == pytest.approx(1700000000.25)
    assert bytes(raw.payload()) == jpeg
    arr, enc = decode_compressed(raw.payload(), raw.format)
    assert enc == 'bgr8' and arr.shape == (48, 64, 3)
    with pytest.raises(InputError, match='cut short'):
        parse_compressed_cdr(serialize_message(msg)[:-100])
    with pytest.raises(InputError, match='not a serialized'):
        parse_compressed_cdr(b'\x00\x01')
