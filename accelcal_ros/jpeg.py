"""
JPEG encoding, the one place every encoder of the package goes through (pure core).

:func:`encode_jpeg` writes a baseline JPEG of an 8-bit image (grey, or three channels in
BGR or RGB order) with 4:2:0 chroma subsampling, as ``cv2.imencode`` does by default, so
the files and their sizes are those OpenCV writes. It uses libjpeg-turbo through
``simplejpeg`` when that package is installed and ``cv2.imencode`` otherwise: the
OpenCV 4.6 wheel (the Ubuntu 24.04 stack of the tests) encodes without libjpeg-turbo's
SIMD. Measured (1280x720 BGR, quality 80, CPU time of one thread, one 2-core machine):
``cv2.imencode`` 18-25 ms on OpenCV 4.6, 4.0-5.0 ms on OpenCV 5.0; ``simplejpeg`` 3.5-4.1
ms on both, the output within 1 % of OpenCV's size. Who encodes: the levelled views in
a browser (``accelcal serve``, the stitcher's page), ``panorama/compressed`` and
image_transport's compressed format (:func:`~accelcal_ros.rosutil.compressed.
encode_compressed`).

Both libraries release the GIL while they encode: views encode in parallel in threads.
"""
from typing import Optional

from accelcal_ros.errors import InputError
import numpy as np

try:
    import simplejpeg
except ImportError:   # optional (package.xml): OpenCV encodes then
    simplejpeg = None

ENCODERS = ('simplejpeg', 'opencv')
"""What :func:`encode_jpeg` may use, fastest first."""


def encoder() -> str:
    """Return the encoder :func:`encode_jpeg` uses by default (one of :data:`ENCODERS`)."""
    return 'simplejpeg' if simplejpeg is not None else 'opencv'


def encode_jpeg(image: np.ndarray, quality: int = 90, rgb: bool = False,
                use: Optional[str] = None) -> bytes:
    """
    Return the JPEG of an 8-bit ``image``: (H, W), (H, W, 1) grey or (H, W, 3) colour.

    ``quality`` 1-100; ``rgb``: the three channels are in RGB order (else BGR, OpenCV's);
    ``use``: an encoder of :data:`ENCODERS` (None: :func:`encoder`). Raises
    :class:`~accelcal_ros.errors.InputError` for another image or a failed encoding.
    """
    arr = np.asarray(image)
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if arr.dtype != np.uint8 or not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] == 3)) \
            or arr.shape[0] < 1 or arr.shape[1] < 1:
        raise InputError(f'JPEG needs an 8-bit grey or 3-channel image, got {arr.dtype} '
                         f'{arr.shape}')
    if not 1 <= int(quality) <= 100:
        raise InputError(f'JPEG quality {quality!r}: use 1 to 100')
    use = use or encoder()
    if use not in ENCODERS or (use == 'simplejpeg' and simplejpeg is None):
        raise InputError(f'JPEG encoder {use!r} is not available (installed: {encoder()})')
    if use == 'simplejpeg':
        grey = arr.ndim == 2
        try:
            return bytes(simplejpeg.encode_jpeg(
                np.ascontiguousarray(arr[:, :, None] if grey else arr), quality=int(quality),
                colorspace='GRAY' if grey else ('RGB' if rgb else 'BGR'),
                colorsubsampling='Gray' if grey else '420'))
        except (ValueError, RuntimeError) as exc:
            raise InputError(f'JPEG encoding of a {arr.shape} image failed: {exc}') from None
    import cv2

    if rgb and arr.ndim == 3:
        arr = cv2.cvtColor(arr, cv2.COLOR_RGB2BGR)
    ok, data = cv2.imencode('.jpg', arr, [cv2.IMWRITE_JPEG_QUALITY, int(quality)])
    if not ok:
        raise InputError(f'JPEG encoding of a {arr.shape} image failed')
    return data.tobytes()
