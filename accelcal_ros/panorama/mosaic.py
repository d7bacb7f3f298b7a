"""
The mosaic: every camera image of a rig side by side in one image.

A whole panorama frame is then one ``cv2.remap`` of the mosaic (:mod:`.stitch`). Images
are separated from each other and from the mosaic's edges by ``gap`` black pixels, so
that bilinear interpolation next to a frame edge fades to black, as it does outside a
lone frame. Pixel coordinates follow OpenCV (integers at pixel centres).
"""
from dataclasses import dataclass
from typing import Any

from accelcal_ros.errors import InputError

OUTSIDE = -1000.0
"""Map value of a pixel no camera sees: far outside the mosaic, so ``cv2.remap`` gives 0."""
FIXED_POINT_LIMIT = 32000
"""Mosaic sides are kept below this so maps convert to OpenCV's 16-bit fixed point."""


@dataclass(frozen=True)
class MosaicLayout:
    """
    Where each camera's image sits in the mosaic: ``offsets[i] = (x0, y0)``, size, gap.

    Images are separated from each other and from the mosaic's edges by ``gap`` black
    pixels.
    """

    offsets: tuple
    width: int
    height: int
    gap: int

    @classmethod
    def for_rig(cls, rig: Any, gap: int = 32, limit: int = FIXED_POINT_LIMIT) -> 'MosaicLayout':
        """Place the images left to right, wrapping to a new row before ``limit`` px."""
        offsets, x, y, row_h, width = [], gap, gap, 0, 0
        for cam in rig.cameras:
            if cam.width + 2 * gap > limit:
                raise InputError(f'camera {cam.name!r}: width {cam.width} exceeds {limit}')
            if x + cam.width + gap > limit:
                x, y, row_h = gap, y + row_h + gap, 0
            offsets.append((x, y))
            x += cam.width + gap
            row_h = max(row_h, cam.height)
            width = max(width, x)
        height = y + row_h + gap
        if height > limit:
            raise InputError(f'rig images do not fit a {limit}x{limit} mosaic')
        return cls(tuple(offsets), width, height, gap)
