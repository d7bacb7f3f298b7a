r"""
A levelled view rendered by one homography per camera (no lookup map to rebuild).

A view pixel ``p = (u, v, 1)`` has the ray ``A_i T p`` in camera ``i``, with
``A_i = Q_i R_PV diag(1, 1, f)`` (:meth:`.view.ViewLookupBuilder.camera_rotations`: the
panorama's eq. 7 tilt, the view's direction and zoom) and ``T`` the shift by
``(c_x, c_y)``. Up to the lens, that is a homography: in the camera's *undistorted*
image plane (a pinhole camera ``K_u``) the view pixel lands on ``K_u A_i T p``. So:

1. Each camera's undistorted plane is resampled from the mosaic through a fixed map
   built once from the rig's lens model (:meth:`~.rig_projection.RigProjection.evaluate`
   with that camera only: the same ``K_i``, ``D_i``, validity limit and "outside the
   frame is black" rule as the panorama, no second copy), and only over the rectangle
   the views need, once per frame set for all the views that share it
   (:class:`CameraPlanes`).
2. The camera choice (eq. 6: the largest ``z``) between cameras ``i`` and ``j`` is
   ``(a_i - a_j) T p >= 0`` with ``a_i`` the third row of ``A_i``: a half-plane of the
   view (a great circle is a straight line in a rectilinear view). Camera ``i``'s pixels
   are those whose centres satisfy its half-planes -- against every other camera, in
   front (``z_i > 0``) and within its plane's extent --: a convex region, per row one
   interval of columns (:class:`WarpPlan`). Each region is filled by
   ``cv2.warpPerspective`` of the camera's plane (the view's map is computed inside
   OpenCV tile by tile, never stored) in bands of rows: each band's columns that all its
   rows hold straight, the rest through a mask of the region's pixels.
3. Planes and warps use 4 channels for a colour view (OpenCV warps 8-bit 4-channel
   images about twice as fast as 3-channel ones); the frame is converted back at the end.

The geometry is exact (no interpolation of a map); the price is a second resampling
of the image (the undistortion, at ``plane_scale`` times the camera's focal length:
1.5 by default), a slight blur measured by ``test/panorama/test_view.py`` against
rendered ground truth.
"""
import math
import threading
from typing import Any, cast, Dict, List, Optional, Tuple

from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.rig_projection import frame_border_pixels, normalized_from_pixels
import numpy as np

Rect = Tuple[int, int, int, int]
"""``(x0, y0, x1, y1)``, end exclusive."""
BAND_ROWS = 240
"""A camera's part of a view is drawn in bands of about this many rows (each band's
straight rectangle as wide as its rows allow; the rest through a mask)."""
Part = Tuple[int, np.ndarray, Rect, Optional[np.ndarray]]
"""A piece of a view: camera, homography, rectangle, per row columns (or None: all)."""
DEFAULT_PLANE_SCALE = 1.5
"""Pixels of an undistorted plane per pixel of its camera (at the image centre)."""


def grow(done: Optional[Rect], need: Rect) -> Tuple[List[Rect], Rect]:
    """
    Return the rectangles to add to ``done`` so that it holds ``need``, and their union.

    Work done per frame set over a rectangle of a camera's image (resampling, colour
    conversion) is grown to what a view needs: a view moving over one frame set does a
    strip, not its whole need. Some returned rectangles may be empty (``x1 <= x0``).
    """
    if done is None:
        return [need], need
    u = (min(need[0], done[0]), min(need[1], done[1]), max(need[2], done[2]),
         max(need[3], done[3]))
    return [(u[0], u[1], u[2], done[1]), (u[0], done[3], u[2], u[3]),
            (u[0], done[1], done[0], done[3]), (done[2], done[1], u[2], done[3])], u


class CameraPlanes:
    """
    The rig cameras' undistorted image planes, resampled from a mosaic on demand.

    ``projection`` is a :class:`~.rig_projection.RigProjection` over the mosaic layout
    (a view's builder); ``plane_scale`` sets each plane's focal length to that many times
    the camera's larger one. Planes are filled per frame set: :meth:`prepare` resamples
    the rectangles asked for that are not done yet for that ``version`` of the mosaic
    (thread-safe: views drawing one ``version`` at once share the planes; what one
    resamples lies outside what the others read).
    """

    def __init__(self, projection: Any, plane_scale: float = DEFAULT_PLANE_SCALE) -> None:
        import cv2

        self._cv2 = cv2
        rig = projection.rig
        offsets = np.asarray(projection.layout.offsets, np.float32)
        self.intrinsics: List[np.ndarray] = []
        self.sizes: List[Tuple[int, int]] = []
        self.maps: List[Tuple[np.ndarray, np.ndarray]] = []
        self.extents: List[Tuple[float, float, float, float]] = []
        identity = np.repeat(np.eye(3)[None], len(rig), axis=0)
        for i, cam in enumerate(rig.cameras):
            xn, yn = normalized_from_pixels(cam, *frame_border_pixels(cam, 1.0))
            f = plane_scale * max(cam.K[0, 0], cam.K[1, 1])
            x0, x1 = float(xn.min()), float(xn.max())
            y0, y1 = float(yn.min()), float(yn.max())
            width = int(math.ceil((x1 - x0) * f)) + 3
            height = int(math.ceil((y1 - y0) * f)) + 3
            k = np.array([[f, 0.0, 1.0 - x0 * f], [0.0, f, 1.0 - y0 * f], [0.0, 0.0, 1.0]])
            px = np.empty((height, width), np.float32)
            py = np.empty_like(px)
            side = np.empty((height, width), np.uint8)
            xs = ((np.arange(width) - k[0, 2]) / f).astype(np.float32)
            for r0 in range(0, height, 128):  # in bands of rows: bounded memory
                ys = ((np.arange(r0, min(height, r0 + 128)) - k[1, 2]) / f).astype(np.float32)
                rays = np.empty((3, len(ys), width), np.float32)
                rays[0] = xs[None, :]
                rays[1] = ys[:, None]
                rays[2] = 1.0
                _, bx, by, bs = projection._evaluate_soa(rays.reshape(3, -1), identity,
                                                         only=i)
                px[r0:r0 + len(ys)] = bx.reshape(len(ys), width)
                py[r0:r0 + len(ys)] = by.reshape(len(ys), width)
                side[r0:r0 + len(ys)] = bs.reshape(len(ys), width)
            # A plane pixel is black unless its point is farther inside the frame's
            # bilinear support than one plane pixel spans: a view pixel whose point lies
            # outside that support (black in the lookup) then reads black plane pixels
            # only, whichever of them surround it.
            span = self._span(px, py, side == 0)
            outside = (side != 0) | (px <= span - 1.0) | (px >= cam.width - span) | \
                (py <= span - 1.0) | (py >= cam.height - span)
            fine = np.stack([px + offsets[i, 0], py + offsets[i, 1]], axis=-1)
            fine[outside] = OUTSIDE
            self.maps.append(cv2.convertMaps(fine, cast(Any, None), cv2.CV_16SC2))
            self.intrinsics.append(k)
            self.sizes.append((width, height))
            # the plane's extent in normalized coordinates (its pixel edges)
            self.extents.append(((-0.5 - k[0, 2]) / f, (width - 0.5 - k[0, 2]) / f,
                                 (-0.5 - k[1, 2]) / f, (height - 0.5 - k[1, 2]) / f))
        self.images: Optional[List[np.ndarray]] = None
        self._staging: List[np.ndarray] = []
        self._done: List[Optional[Rect]] = [None] * len(rig)
        self._version: Any = object()
        self._lock = threading.Lock()

    @staticmethod
    def _span(px: np.ndarray, py: np.ndarray, valid: np.ndarray) -> float:
        """Largest camera-pixel step between diagonal neighbours of the plane (valid ones)."""
        both = valid[1:, 1:] & valid[:-1, :-1] & valid[1:, :-1] & valid[:-1, 1:]
        if not both.any():
            return 0.0
        steps = [np.abs(px[1:, :-1] - px[:-1, :-1]) + np.abs(px[:-1, 1:] - px[:-1, :-1]),
                 np.abs(py[1:, :-1] - py[:-1, :-1]) + np.abs(py[:-1, 1:] - py[:-1, :-1])]
        return 1.01 * max(float(step[both].max()) for step in steps)

    def holds(self, version: Any) -> bool:
        """Return True when some plane was resampled from the mosaic's ``version``."""
        with self._lock:
            return version is not None and version == self._version and \
                any(done is not None for done in self._done)

    def prepare(self, mosaic: np.ndarray, needs: Dict[int, Rect], version: Any = None) -> None:
        """
        Resample the rectangles ``needs`` (camera -> plane rectangle) from ``mosaic``.

        With ``version`` (any value that changes with the mosaic's content), rectangles
        done earlier for the same version are reused; None resamples every time.
        """
        with self._lock:
            self._prepare(mosaic, needs, version)

    def _prepare(self, mosaic: np.ndarray, needs: Dict[int, Rect], version: Any) -> None:
        """:meth:`prepare`, holding the lock."""
        cv2 = self._cv2
        colour = mosaic.ndim == 3 and mosaic.shape[2] == 3
        channels = (4,) if colour else mosaic.shape[2:]
        if self.images is None or self.images[0].shape[2:] != channels or \
                self.images[0].dtype != mosaic.dtype:
            self.images = [np.zeros((h, w) + channels, mosaic.dtype) for w, h in self.sizes]
            self._staging = [np.zeros((h, w) + mosaic.shape[2:], mosaic.dtype)
                             for w, h in self.sizes] if colour else self.images
            self._version = object()
        if version is None or version != self._version:
            self._done = [None] * len(self._done)
            self._version = object() if version is None else version
        for i, need in needs.items():
            parts, done = grow(self._done[i], need)   # resample only what is new
            for x0, y0, x1, y1 in parts:
                if x1 <= x0 or y1 <= y0:
                    continue
                map1, map2 = self.maps[i]
                staged = self._staging[i][y0:y1, x0:x1]
                cv2.remap(mosaic, map1[y0:y1, x0:x1], map2[y0:y1, x0:x1], cv2.INTER_LINEAR,
                          dst=staged, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                if colour:  # OpenCV warps 4 channels about twice as fast as 3
                    cv2.cvtColor(staged, cv2.COLOR_BGR2BGRA,
                                 dst=self.images[i][y0:y1, x0:x1])
            self._done[i] = done


class WarpPlan:
    """
    Where each camera fills a view: pixel rows, homographies, plane rectangles (one pose).

    ``rotations`` are ``A_i`` (n, 3, 3): view pixel offsets ``(u - c_x, v - c_y, 1)`` ->
    camera ``i``; ``planes`` the :class:`CameraPlanes`. Camera ``i``'s pixels are those
    whose centres satisfy every one of its half-planes (in front, eq. 6 against each
    other camera, within its plane): per row an interval of columns, the region being
    convex.
    """

    def __init__(self, rotations: np.ndarray, planes: CameraPlanes, width: int, height: int,
                 cx: float, cy: float) -> None:
        shift = np.array([[1.0, 0.0, -cx], [0.0, 1.0, -cy], [0.0, 0.0, 1.0]])
        a = np.asarray(rotations, float) @ shift  # view pixel (u, v, 1) -> camera i
        self.width, self.height = width, height
        self.rotations = a
        """``A_i`` with the shift: view pixel ``(u, v, 1)`` -> camera ``i`` (n, 3, 3)."""
        self._parts: Optional[List[Part]] = None
        self._planes = planes
        self._needs: Optional[Dict[int, Rect]] = None
        self._homographies: Dict[int, np.ndarray] = {}
        self.regions: Dict[int, Tuple[int, np.ndarray, np.ndarray]] = {}
        """Camera ``i``'s region: first row ``y0`` and per row its first and last column."""
        z = a[:, 2]
        ext = np.asarray(planes.extents)  # (n, 4): x0, x1, y0, y1
        front = z.copy()
        front[:, 2] -= 1e-9 * max(width, height) * np.abs(z).sum(axis=1)
        lines = np.concatenate([
            front[:, None], z[:, None] - z[None, :],
            (a[:, 0] - ext[:, 0:1] * z)[:, None], (ext[:, 1:2] * z - a[:, 0])[:, None],
            (a[:, 1] - ext[:, 2:3] * z)[:, None], (ext[:, 3:4] * z - a[:, 1])[:, None]],
            axis=1)  # (n, 1 + n + 4, 3); camera i against itself: 0 >= 0, always true
        corners = np.array([[-0.5, -0.5, 1.0], [width - 0.5, -0.5, 1.0],
                            [-0.5, height - 0.5, 1.0], [width - 0.5, height - 0.5, 1.0]])
        at_corners = lines @ corners.T  # (n, lines, 4)
        tiny = 1e-12 * (np.abs(lines).sum(axis=2) + 1e-300)
        # a camera whose region misses the view (all four corners beyond one of its
        # half-planes) is left out; a half-plane holding the whole view (every corner
        # farther in than ``tiny``) bounds no row: only the others are worked row by row
        keep = ~(at_corners < 0).all(axis=2).any(axis=1)
        active = (at_corners.min(axis=2) <= tiny) & keep[:, None]
        cam_of, line_of = np.nonzero(active)
        active_lines = lines[cam_of, line_of]  # (m, 3)
        v = np.arange(height, dtype=float)
        coef = active_lines[:, 0:1]
        rest = active_lines[:, 1:2] * v + active_lines[:, 2:3]  # (m, rows)
        small = tiny[cam_of, line_of][:, None]
        bound = -rest / np.where(np.abs(coef) > small, coef, 1.0)  # used where |coef| > small
        lo_all = np.where(coef > small, np.ceil(bound), 0.0)
        hi_all = np.where(coef < -small, np.floor(bound), width - 1.0)
        hi_all[(np.abs(coef) <= small) & (rest < 0)] = -1.0
        starts = np.searchsorted(cam_of, np.arange(len(a) + 1))
        for i in np.flatnonzero(keep):
            lo = np.maximum(lo_all[starts[i]:starts[i + 1]].max(axis=0, initial=0.0), 0.0)
            hi = np.minimum(hi_all[starts[i]:starts[i + 1]].min(axis=0, initial=width - 1.0),
                            width - 1.0)
            rows = np.flatnonzero(lo <= hi)
            if rows.size == 0:
                continue
            y0, y1 = int(rows[0]), int(rows[-1]) + 1  # a convex region: one run of rows
            self.regions[int(i)] = (y0, lo[y0:y1].astype(np.int32), hi[y0:y1].astype(np.int32))
        self._blank_rows: Optional[List[Tuple[int, int]]] = None
        self._masks: Dict[int, np.ndarray] = {}

    def homography(self, i: int) -> np.ndarray:
        """Return camera ``i``'s homography: view pixel -> pixel of its undistorted plane."""
        h = self._homographies.get(i)
        if h is None:
            h = self._homographies[i] = self._planes.intrinsics[i] @ self.rotations[i]
        return h

    @property
    def needs(self) -> Dict[int, Rect]:
        """
        Return per camera the rectangle of its plane the regions read (made on first use).

        The hull of its rows' ends mapped into the plane, with the bilinear taps.
        """
        if self._needs is None:
            self._needs = {}
            for i, (y0, li, hi_i) in self.regions.items():
                y1 = y0 + len(li)
                ends = np.stack([np.concatenate([li, hi_i]).astype(float),
                                 np.tile(np.arange(y0, y1, dtype=float), 2),
                                 np.ones(2 * (y1 - y0))])
                mapped = self.homography(i) @ ends
                px, py = mapped[0] / mapped[2], mapped[1] / mapped[2]
                pw, ph = self._planes.sizes[i]
                need = (max(0, int(math.floor(px.min())) - 2),
                        max(0, int(math.floor(py.min())) - 2),
                        min(pw, int(math.ceil(px.max())) + 3),
                        min(ph, int(math.ceil(py.max())) + 3))
                if need[2] > need[0] and need[3] > need[1]:
                    self._needs[i] = need
        return self._needs

    @property
    def blank_rows(self) -> List[Tuple[int, int]]:
        """Return the runs of rows ``[r0, r1)`` some pixel of which no camera's region holds."""
        if self._blank_rows is None:
            width, height = self.width, self.height
            first = np.full(height, width, np.int64)
            last = np.full(height, -1, np.int64)
            widths = np.zeros(height, np.int64)
            for y0, li, hi_i in self.regions.values():
                y1 = y0 + len(li)
                np.minimum(first[y0:y1], li, out=first[y0:y1])
                np.maximum(last[y0:y1], hi_i, out=last[y0:y1])
                widths[y0:y1] += hi_i - li + 1
            short = (first > 0) | (last < width - 1) | (widths < width)
            edges = np.flatnonzero(np.diff(np.concatenate([[0], short.view(np.int8), [0]])))
            self._blank_rows = [(int(r0), int(r1)) for r0, r1 in zip(edges[::2], edges[1::2])]
        return self._blank_rows

    @property
    def parts(self) -> List[Part]:
        """
        Return the pieces to draw (:data:`Part`), made on first use.

        Each: ``(camera, homography from the piece's origin, rectangle, the columns to
        take within it per row (2, rows: first, last) or None for all of them)``. Made
        on first use (the ``'grid'`` renderer needs only :attr:`regions`).
        """
        if self._parts is None:
            self._parts = []
            for i, (y0, li, hi_i) in self.regions.items():
                if i not in self.needs:
                    continue
                h = self.homography(i)
                y1 = y0 + len(li)
                # per band of rows, the columns every row of the band holds are drawn
                # straight; the slivers left and right of them through a mask of the pixels
                # whose centres lie in the region (a slanted seam, a tapering corner)
                count = y1 - y0
                step = count if count <= 2 * BAND_ROWS else -(-count // -(-count // BAND_ROWS))
                for r0 in range(0, count, step):
                    r1 = min(count, r0 + step)
                    bl, bh = li[r0:r1], hi_i[r0:r1]
                    b0, b1 = int(bl.min()), int(bh.max()) + 1
                    inner0, inner1 = int(bl.max()), int(bh.min()) + 1
                    if inner1 <= inner0:
                        inner0 = inner1 = b0
                    else:
                        self._piece(i, h, (inner0, y0 + r0, inner1, y0 + r1), None)
                    for s0, s1 in ((b0, inner0), (inner1, b1)):
                        if s1 > s0:
                            self._sliver(i, h, s0, s1, y0 + r0, bl, bh)
        return self._parts

    def _piece(self, i: int, h: np.ndarray, rect: Rect, columns: Optional[np.ndarray]) -> None:
        m = h @ np.array([[1.0, 0.0, rect[0]], [0.0, 1.0, rect[1]], [0.0, 0.0, 1.0]])
        assert self._parts is not None
        self._parts.append((i, m, rect, columns))

    def _sliver(self, i: int, h: np.ndarray, s0: int, s1: int, y0: int, lo: np.ndarray,
                hi: np.ndarray) -> None:
        """Add columns ``s0 .. s1 - 1`` of the region (rows ``y0 + k``: ``lo .. hi``)."""
        a, b = np.maximum(lo, s0), np.minimum(hi, s1 - 1)
        rows = np.nonzero(a <= b)[0]
        if rows.size == 0:
            return
        k0, k1 = int(rows[0]), int(rows[-1]) + 1  # a convex region: one run of rows
        self._piece(i, h, (s0, y0 + k0, s1, y0 + k1),
                    np.stack([a[k0:k1] - s0, b[k0:k1] - s0]))

    def mask(self, k: int) -> np.ndarray:
        """
        Return the pixels of sliver part ``k`` in its region (uint8, 1 in it, else 0).

        Drawn by ``cv2.fillPoly`` through each row's first and last column (integer
        vertices on every row: exactly the rows' column ranges), cached with the plan.
        """
        import cv2

        mask = self._masks.get(k)
        if mask is None:
            _, _, (x0, y0, x1, y1), poly = self.parts[k]
            assert poly is not None
            mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
            rows = np.arange(y1 - y0, dtype=np.int32)
            edge = np.concatenate([np.stack([poly[0], rows], axis=1),
                                   np.stack([poly[1], rows], axis=1)[::-1]])
            cv2.fillPoly(mask, [edge.astype(np.int32)], 1)
            self._masks[k] = mask
        return mask

    def blank(self, canvas: np.ndarray) -> None:
        """Black out the rows of ``canvas`` some pixel of which no camera's region holds."""
        for r0, r1 in self.blank_rows:
            canvas[r0:r1] = 0

    def render(self, planes: CameraPlanes, out: np.ndarray, canvas: np.ndarray,
               scratch: np.ndarray) -> None:
        """
        Fill ``out`` (H, W[, 3]) from the planes (prepared for :attr:`needs`).

        ``canvas`` and ``scratch`` are buffers of the planes' channels (4 for a colour
        view, whose canvas is converted to ``out`` at the end; for grey, ``canvas`` may
        be ``out``).
        """
        import cv2

        assert planes.images is not None
        self.blank(canvas)
        flags = cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP
        for k, (i, m, (x0, y0, x1, y1), poly) in enumerate(self.parts):
            src = planes.images[i]
            if poly is None:
                cv2.warpPerspective(src, m, (x1 - x0, y1 - y0), dst=canvas[y0:y1, x0:x1],
                                    flags=flags, borderMode=cv2.BORDER_CONSTANT,
                                    borderValue=0)
                continue
            part = scratch[y0:y1, x0:x1]
            cv2.warpPerspective(src, m, (x1 - x0, y1 - y0), dst=part, flags=flags,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=0)
            cv2.copyTo(part, self.mask(k), canvas[y0:y1, x0:x1])
        if canvas is not out:
            cv2.cvtColor(canvas, cv2.COLOR_BGRA2BGR, dst=out)
