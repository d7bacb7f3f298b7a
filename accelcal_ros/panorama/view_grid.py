r"""
A levelled view rendered straight from the camera images: one ``cv2.remap`` per camera part.

The :class:`~.view_warp.WarpPlan` of a pose splits the view into each camera's convex
region (eq. 6's half-planes, the camera's front and its frame's extent) and those into
pieces (rectangles drawn whole, slivers through a mask). Here each piece is one
``cv2.remap`` from the camera's own image (no undistorted plane in between: one
resampling of the image, as the lookup renderer), with a map that is, per camera, a
smooth function of the view pixel (the camera's homography, then its lens):

1. The map is evaluated exactly on a coarse grid over the bounding box of the camera's
   region (:meth:`~.rig_projection.RigProjection._evaluate_soa` with that camera only:
   the same ``K_i``, ``D_i`` as the panorama, no second copy), every
   :data:`GRID_STEP_PX` view pixels, half a cell beyond the box on every side;
2. ``cv2.resize`` (bilinear) spreads it to every pixel of the box: its sample positions
   ``(x + 1/2) / s - 1/2`` fall exactly on the nodes' placement, and the half cell of
   margin keeps the box's pixels off the resize's clamped border. The error of the
   bilinear interpolation is measured against the exact lens by
   ``test/panorama/test_view_grid.py`` (:data:`GRID_STEP_PX` is chosen for it);
3. Pixels outside the camera's frame read OpenCV's constant border: black, as the
   panorama's rule. A colour view is drawn in 4 channels (cameras converted once per
   frame set for all the views: OpenCV 5 remaps 8-bit 4-channel images from float maps
   about twice as fast as 3-channel ones, OpenCV 4.6 about as fast) and converted back.

Per pose: the plan and the coarse maps (the part that moves with the view); per frame
set: the 4-channel camera images; per frame: the remaps.
"""
from typing import Any, cast, Dict, List, Tuple

from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.view_warp import Rect, WarpPlan
import numpy as np

GRID_STEP_PX = 16
"""View pixels between the exactly evaluated nodes of a camera's map (halved, twice at
most, while the error at the cells' centres exceeds :data:`CHECK_FRACTION` of the
tolerance)."""
CHECK_FRACTION = 0.75
"""Share of ``tolerance_px`` the error at a cell's centre may reach (as the lookup's)."""


class CameraSources:
    """
    The rig cameras' images as the remaps read them, per frame set (shared by views).

    ``layout`` is the mosaic's :class:`~.mosaic.MosaicLayout`; :meth:`get` returns camera
    ``i``'s part of the mosaic: for a colour mosaic a 4-channel copy of which only the
    rectangle asked for is sure to be converted (once per ``version``: a view asking for
    more converts only what is new), for grey the mosaic's own slice.
    """

    def __init__(self, layout: Any, sizes: List[Tuple[int, int]]) -> None:
        self.offsets = [(int(x), int(y)) for x, y in layout.offsets]
        self.sizes = sizes
        self._done: Dict[int, Rect] = {}
        self._buffers: Dict[int, np.ndarray] = {}
        self._version: Any = object()

    def get(self, mosaic: np.ndarray, i: int, rect: Rect, version: Any = None) -> np.ndarray:
        """Return camera ``i``'s image of ``mosaic``, right within ``rect`` (camera pixels)."""
        import cv2

        (x0, y0), (w, h) = self.offsets[i], self.sizes[i]
        part = mosaic[y0:y0 + h, x0:x0 + w]
        if not (mosaic.ndim == 3 and mosaic.shape[2] == 3):
            return part
        if version is None or version != self._version:
            self._done.clear()
            self._version = object() if version is None else version
        buffer = self._buffers.get(i)
        if buffer is None or buffer.shape != (h, w, 4):
            buffer = self._buffers[i] = np.empty((h, w, 4), np.uint8)
        done = self._done.get(i)
        if done is None:
            parts, done = [rect], rect
        else:  # convert only the strips around what is done already
            u = (min(rect[0], done[0]), min(rect[1], done[1]), max(rect[2], done[2]),
                 max(rect[3], done[3]))
            parts = [(u[0], u[1], u[2], done[1]), (u[0], done[3], u[2], u[3]),
                     (u[0], done[1], done[0], done[3]), (done[2], done[1], u[2], done[3])]
            done = u
        for a0, b0, a1, b1 in parts:
            if a1 > a0 and b1 > b0:
                cv2.cvtColor(part[b0:b1, a0:a1], cv2.COLOR_BGR2BGRA, dst=buffer[b0:b1, a0:a1])
        self._done[i] = done
        return buffer


class GridMaps:
    """
    Each camera's map over its part of one pose's view (view pixel -> camera pixel).

    ``plan`` is the pose's :class:`~.view_warp.WarpPlan`, ``projection`` the view's
    builder (:class:`~.rig_projection.RigProjection`) and ``rotations`` its camera
    rotations ``A_i`` (view pixel offsets -> camera ``i``) with the view's centre
    ``(cx, cy)``.
    """

    def __init__(self, plan: WarpPlan, projection: Any, rotations: np.ndarray, cx: float,
                 cy: float, step: int = GRID_STEP_PX, tolerance_px: float = 0.1) -> None:
        self.plan = plan
        self.worst_px = 0.0
        """The largest interpolation error found at the cells' centres (camera pixels)."""
        self.maps: Dict[int, Tuple[np.ndarray, int, int]] = {}  # camera: (map, x0, y0)
        self.rects: Dict[int, Rect] = {}  # camera: the pixels its map reaches
        boxes: Dict[int, List[int]] = {}
        for i, _, (x0, y0, x1, y1), _ in plan.parts:
            box = boxes.setdefault(i, [x0, y0, x1, y1])
            box[:] = [min(box[0], x0), min(box[1], y0), max(box[2], x1), max(box[3], y1)]
        for i, box in boxes.items():
            for s in (step, step // 2, step // 4):
                fine, ox, oy, error, rect = self._camera_map(projection, rotations, i, box,
                                                             cx, cy, max(2, s))
                if error <= CHECK_FRACTION * tolerance_px:
                    break
            self.maps[i] = (fine, ox, oy)
            self.rects[i] = rect
            self.worst_px = max(self.worst_px, error)

    @staticmethod
    def _camera_map(projection: Any, rotations: np.ndarray, i: int, box: List[int],
                    cx: float, cy: float, step: int
                    ) -> Tuple[np.ndarray, int, int, float, Rect]:
        """Return camera ``i``'s map over ``box`` at node spacing ``step``, its origin, error."""
        import cv2

        x0, y0, x1, y1 = box
        nx = -(-(x1 - x0 + step) // step)
        ny = -(-(y1 - y0 + step) // step)
        # node k at box pixel k s - 1/2: the resize's sample position of node k is fine
        # pixel (k + 1/2) s - 1/2, the box starting at fine pixel s/2; the cells' centres
        # are evaluated too, to bound the bilinear interpolation's error
        us = (np.arange(nx) * step - 0.5 + x0 - cx).astype(np.float32)
        vs = (np.arange(ny) * step - 0.5 + y0 - cy).astype(np.float32)
        nodes, centres = nx * ny, (nx - 1) * (ny - 1)
        rays = np.empty((3, nodes + centres), np.float32)
        rays[0, :nodes] = np.tile(us, ny)
        rays[1, :nodes] = np.repeat(vs, nx)
        rays[0, nodes:] = np.tile(us[:-1] + 0.5 * step, ny - 1)
        rays[1, nodes:] = np.repeat(vs[:-1] + 0.5 * step, nx - 1)
        rays[2] = 1.0
        _, px, py, side = projection._evaluate_soa(rays, rotations, only=i)
        bad = (side & 16) != 0
        px[bad] = OUTSIDE
        py[bad] = OUTSIDE
        coarse = np.stack([px[:nodes], py[:nodes]], axis=-1).reshape(ny, nx, 2)
        centre = np.stack([px[nodes:], py[nodes:]], axis=-1).reshape(ny - 1, nx - 1, 2)
        mean = 0.25 * (coarse[:-1, :-1] + coarse[1:, :-1] + coarse[:-1, 1:] + coarse[1:, 1:])
        b = bad[:nodes].reshape(ny, nx)
        good = ~(b[:-1, :-1] | b[1:, :-1] | b[:-1, 1:] | b[1:, 1:] |
                 bad[nodes:].reshape(ny - 1, nx - 1))
        error = float(np.abs(mean - centre).max(axis=-1)[good].max(initial=0.0))
        w, h = projection.rig.cameras[i].width, projection.rig.cameras[i].height
        ok = ~b
        if ok.any():  # the camera pixels the map can reach, with the bilinear taps
            xs, ys = coarse[..., 0][ok], coarse[..., 1][ok]
            rect = (min(w, max(0, int(np.floor(xs.min())))),
                    min(h, max(0, int(np.floor(ys.min())))),
                    max(0, min(w, int(np.floor(xs.max())) + 2)),
                    max(0, min(h, int(np.floor(ys.max())) + 2)))
        else:
            rect = (0, 0, 0, 0)
        fine = cv2.resize(coarse, (nx * step, ny * step), interpolation=cv2.INTER_LINEAR)
        return fine, x0 - step // 2, y0 - step // 2, error, rect

    def render(self, sources: CameraSources, mosaic: np.ndarray, version: Any,
               out: np.ndarray, canvas: np.ndarray, scratch: np.ndarray) -> None:
        """Fill ``out`` from the cameras' images (``canvas``/``scratch`` as the warp's)."""
        import cv2

        plan = self.plan
        plan.blank(canvas)
        images = {i: sources.get(mosaic, i, rect, version) for i, rect in self.rects.items()}
        for k, (i, _, (x0, y0, x1, y1), poly) in enumerate(plan.parts):
            src = images[i]
            fine, ox, oy = self.maps[i]
            m = fine[y0 - oy:y1 - oy, x0 - ox:x1 - ox]
            if poly is None:
                cv2.remap(src, m, cast(Any, None), cv2.INTER_LINEAR, dst=canvas[y0:y1, x0:x1],
                          borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                continue
            part = scratch[y0:y1, x0:x1]
            cv2.remap(src, m, cast(Any, None), cv2.INTER_LINEAR, dst=part,
                      borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            cv2.copyTo(part, plan.mask(k), canvas[y0:y1, x0:x1])
        if canvas is not out:
            cv2.cvtColor(canvas, cv2.COLOR_BGRA2BGR, dst=out)
