r"""
A levelled view rendered straight from the camera images: one ``cv2.remap`` per frame.

The :class:`~.view_warp.WarpPlan` of a pose splits the view into each camera's convex
region (eq. 6's half-planes, the camera's front and its frame's extent). Here the whole
view is one ``cv2.remap`` from the mosaic of the cameras' own images (no undistorted
plane in between: one resampling of the image, as the lookup renderer), through one map
(view pixel -> mosaic pixel) made per pose (:class:`GridMaps`); each camera's map is a
smooth function of the view pixel over its region (its homography, then its lens):

1. The view is cut into cells of :data:`GRID_STEP_PX` pixels. Every camera is evaluated
   exactly at the corners of the cells its region touches and at their centres
   (:meth:`~.rig_projection.RigProjection._evaluate_runs`, each ray through its own
   camera: the same ``K_i``, ``D_i`` as the panorama, no second copy);
2. A cell inside one camera's region takes that camera's values at its corners, and one
   ``cv2.resize`` (bilinear) per map plane spreads the node grid to every pixel: its
   sample positions ``(x + 1/2) / s - 1/2`` fall exactly on the nodes' placement, and
   half a cell of margin keeps the view off the resize's clamped border;
3. The other cells (seams, frame edges) are filled pixel by pixel: each pixel of a
   region gets the bilinear interpolation of its own camera's corner nodes (the
   resize's weights), the rest ``OUTSIDE``. The error at the cells' centres is checked
   against :data:`CHECK_FRACTION` of the tolerance; the grid halves (twice at most) where
   it is exceeded, and cells still beyond it are evaluated exactly at every pixel.
   ``test/panorama/test_view_grid.py`` measures every pixel against the exact lens.

A pixel just beyond a camera's frame reads the mosaic's black gap (``gap`` pixels:
:attr:`~.mosaic.MosaicLayout.gap`), as the panorama's rule; a node the lens cannot take
or one mapped beyond the gap holds :data:`FAR`, so no pixel reads a neighbour's image.
On OpenCV 5 a colour view is drawn in 4 channels (:data:`FOUR_CHANNELS_FROM`: the
cameras' rectangles the maps reach converted once per frame set for all the views) and
converted back.

Per pose: the plan and the view's map (the part that moves with the view); per frame
set: the 4-channel camera images; per frame: the remap.
"""
from functools import lru_cache
import math
import threading
from typing import Any, Dict, List, Optional, Tuple

from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.view_warp import grow, Rect, WarpPlan
import numpy as np

GRID_STEP_PX = 16
"""View pixels between the exactly evaluated nodes of a camera's map (halved, twice at
most, while the error at the cells' centres exceeds :data:`CHECK_FRACTION` of the
tolerance)."""
FAR = -1.0e8
"""A map node no pixel may read from: a pixel with any weight on it (at least
``1 / (2 s)^2`` at node spacing ``s``) lands far outside the mosaic."""
FOUR_CHANNELS_FROM = 5
"""OpenCV major versions from this one remap a colour view in 4 channels: OpenCV 5.0
remaps an 8-bit 4-channel 1280x720 image from a float map in 4.1 ms against 7.5 ms for
3 channels (one thread), the conversions costing about 1 ms; OpenCV 4.6 takes 7.8 ms
against 8.4 ms, so there the mosaic is remapped as it is."""
CHECK_FRACTION = 0.75
"""Share of ``tolerance_px`` the error at a cell's centre may reach (as the lookup's)."""
TABLES_KEPT_CELLS = 1 << 20
"""Index tables of at most this many (camera, cell) pairs are kept from pose to pose
(:meth:`GridBuffers.tables`: 5 cameras x 1280x720 at step 4 are 0.29 M)."""


def four_channels() -> bool:
    """Return True when a colour view is remapped in 4 channels (:data:`FOUR_CHANNELS_FROM`)."""
    import cv2

    return int(cv2.__version__.split('.')[0]) >= FOUR_CHANNELS_FROM


class CameraSources:
    """
    The rig cameras' images as the remaps read them, per frame set (shared by views).

    ``layout`` is the mosaic's :class:`~.mosaic.MosaicLayout`; :meth:`get` returns camera
    ``i``'s part of the mosaic: for a colour mosaic a 4-channel copy of which only the
    rectangle asked for is sure to be converted (once per ``version``: a view asking for
    more converts only what is new), for grey the mosaic's own slice. Views drawing one
    ``version`` at once may call :meth:`get` from their threads: what one converts lies
    outside what the others read.
    """

    def __init__(self, layout: Any, sizes: List[Tuple[int, int]]) -> None:
        self.offsets = [(int(x), int(y)) for x, y in layout.offsets]
        self.sizes = sizes
        self._done: Dict[int, Rect] = {}
        self._buffer: Optional[np.ndarray] = None
        self._version: Any = object()
        self._lock = threading.Lock()

    def get(self, mosaic: np.ndarray, i: int, rect: Rect, version: Any = None) -> np.ndarray:
        """Return camera ``i``'s image of ``mosaic``, right within ``rect`` (camera pixels)."""
        (x0, y0), (w, h) = self.offsets[i], self.sizes[i]
        part = mosaic[y0:y0 + h, x0:x0 + w]
        if not (mosaic.ndim == 3 and mosaic.shape[2] == 3):
            return part
        with self._lock:
            return self._converted(mosaic, part, i, rect, version)

    def _converted(self, mosaic: np.ndarray, part: np.ndarray, i: int, rect: Rect,
                   version: Any) -> np.ndarray:
        """Return camera ``i``'s 4-channel image, converting what ``rect`` adds (locked)."""
        import cv2

        (x0, y0), (w, h) = self.offsets[i], self.sizes[i]
        if version is None or version != self._version:
            self._done.clear()
            self._version = object() if version is None else version
        buffer = self.image(mosaic)[y0:y0 + h, x0:x0 + w]
        parts, done = grow(self._done.get(i), rect)   # convert only what is new
        for a0, b0, a1, b1 in parts:
            if a1 > a0 and b1 > b0:
                cv2.cvtColor(part[b0:b1, a0:a1], cv2.COLOR_BGR2BGRA, dst=buffer[b0:b1, a0:a1])
        self._done[i] = done
        return buffer

    def image(self, mosaic: np.ndarray) -> np.ndarray:
        """
        Return the whole mosaic as the remaps read it (4 channels for colour, else itself).

        Of a colour mosaic only what :meth:`get` converted is current; the gaps stay black.
        """
        if not (mosaic.ndim == 3 and mosaic.shape[2] == 3):
            return mosaic
        shape = mosaic.shape[:2] + (4,)
        if self._buffer is None or self._buffer.shape != shape:
            self._buffer = np.zeros(shape, np.uint8)
            self._done.clear()
        return self._buffer


class GridBuffers:
    """
    The large arrays a view's :class:`GridMaps` reuse from pose to pose.

    :attr:`maps`: the resized node grid (x and y planes); :meth:`scratch`: the seam cells'
    interpolation; :meth:`tables`: index tables of the node grid. A new array per pose
    cost page faults (a 0.5 MB output allocated per pose took 6-11 ms in one call of six
    on a busy 2-core machine, median 0.2 ms).
    """

    def __init__(self) -> None:
        self.maps: Optional[np.ndarray] = None
        self._scratch = np.empty(0, np.float32)
        self._tables: Dict[Tuple[Any, ...], Dict[str, np.ndarray]] = {}

    def tables(self, step: int, cameras: int, nyc: int, nxc: int, cx: float,
               cy: float) -> Dict[str, np.ndarray]:
        """
        Return :func:`_index_tables` for these arguments.

        Kept for the next poses unless large (a view of millions of cells at a halved
        step: about 30 bytes per camera and cell; those are made per pose).
        """
        key = (step, cameras, nyc, nxc, cx, cy)
        tables = self._tables.get(key)
        if tables is None:
            tables = _index_tables(*key)
            if cameras * nyc * nxc <= TABLES_KEPT_CELLS:
                if len(self._tables) >= 4:
                    self._tables.clear()
                self._tables[key] = tables
        return tables

    def scratch(self, rows: int, columns: int) -> np.ndarray:
        """Return a float32 ``(rows, columns)`` array (its contents undefined)."""
        need = rows * columns
        if self._scratch.size < need:
            self._scratch = np.empty(max(need, 2 * self._scratch.size), np.float32)
        return self._scratch[:need].reshape(rows, columns)


def _index_tables(s: int, cameras: int, nyc: int, nxc: int, cx: float,
                  cy: float) -> Dict[str, np.ndarray]:
    """
    Return per flat index what depends only on the view's size, the step and the cameras.

    Nodes ``(camera, row b, column a)`` of ``cameras x (nyc + 1) x (nxc + 1)``:
    ``node_u``/``node_v``, the view pixel offsets ``(a s - 1/2 - cx, b s - 1/2 - cy)``
    (float32); cells ``(camera, b, a)`` of ``cameras x nyc x nxc``: ``cell_u``/``cell_v``,
    their centres' offsets, and ``cell_node`` their top left node.
    """
    ny, nx = nyc + 1, nxc + 1
    b, a = np.divmod(np.arange(ny * nx), nx)
    hb, ha = np.divmod(np.arange(nyc * nxc), nxc)
    cell_cam = np.repeat(np.arange(cameras), nyc * nxc)
    return {
        'node_u': np.tile((a * s - 0.5 - cx).astype(np.float32), cameras),
        'node_v': np.tile((b * s - 0.5 - cy).astype(np.float32), cameras),
        'cell_u': np.tile((ha * s + (0.5 * s - 0.5) - cx).astype(np.float32), cameras),
        'cell_v': np.tile((hb * s + (0.5 * s - 0.5) - cy).astype(np.float32), cameras),
        'cell_node': (cell_cam * ny + np.tile(hb, cameras)) * nx + np.tile(ha, cameras)}


@lru_cache(maxsize=8)
def _weights(step: int) -> np.ndarray:
    """
    Return the bilinear weights of a cell's ``step x step`` pixels, ``(4, step^2)``.

    Rows: the corners (top left, top right, bottom left, bottom right); a pixel
    ``(dy, dx)`` of the cell lies ``((dy + 1/2) / step, (dx + 1/2) / step)`` from its top
    left node, as ``cv2.resize`` samples it.
    """
    t = (np.arange(step) + 0.5) / step
    wy, wx = np.meshgrid(t, t, indexing='ij')
    return np.stack([(1 - wy) * (1 - wx), (1 - wy) * wx, wy * (1 - wx), wy * wx]).reshape(
        4, step * step).astype(np.float32)


class GridMaps:
    """
    One map over one pose's view (view pixel -> mosaic pixel), each camera's part in it.

    ``plan`` is the pose's :class:`~.view_warp.WarpPlan`, ``projection`` the view's builder
    (:class:`~.rig_projection.RigProjection`) and ``rotations`` its camera rotations ``A_i`` (view
    pixel offsets -> camera ``i``) with the view's centre ``(cx, cy)``. The view is cut into cells
    of :attr:`step` pixels whose corners are the nodes (view pixel ``(a s - 1/2, b s - 1/2)``);
    each camera is evaluated exactly at the nodes of the cells its region touches and at their
    centres, to check the interpolation's error (one
    :meth:`~.rig_projection.RigProjection._evaluate_runs` call for all of them, camera by camera).
    A cell inside one camera's region (*pure*) takes that camera's values at its corners, spread to
    every pixel by ``cv2.resize`` of the node grid; a cell no region touches reads ``OUTSIDE``; the
    others -- seams, frame edges, and pure cells a corner of which another kind of cell takes too
    -- are filled pixel by pixel, each pixel of a region with the bilinear interpolation of its
    camera's nodes (the resize's weights), the rest ``OUTSIDE``. The map is planar (:attr:`map_x`,
    :attr:`map_y`: ``cv2.remap`` takes both; OpenCV 4.6 and 5.0 remap and resize planes a little
    faster), windows of :attr:`buffer`, which is reused for the next pose with :attr:`buffers`.
    """

    def __init__(self, plan: WarpPlan, projection: Any, rotations: np.ndarray, cx: float,
                 cy: float, step: int = GRID_STEP_PX, tolerance_px: float = 0.1,
                 buffers: Optional[GridBuffers] = None) -> None:
        self.plan = plan
        self.worst_px = 0.0
        """The largest interpolation error found at the cells' centres (camera pixels)."""
        self._cams = np.array(sorted(plan.regions), np.intp)
        self._layout = projection.layout
        self._sizes = [(c.width, c.height) for c in projection.rig.cameras]
        self._rects: Optional[Dict[int, Rect]] = None
        self._lens = (projection, rotations, cx, cy)
        self.buffers = buffers if buffers is not None else GridBuffers()
        """Arrays reused from pose to pose (pass them to the next pose's maps)."""
        limit = CHECK_FRACTION * tolerance_px
        for s in sorted({max(2, (step >> k) & ~1) for k in range(3)}, reverse=True):
            cells = self._cells(s)
            values, far = self._evaluate(projection, rotations, cx, cy, s, cells[2])
            if self.worst_px <= limit:
                break
        # cells still beyond the limit at the finest step are evaluated pixel by pixel
        cell, error = self._cell_error
        beyond = error > limit
        self._exact = np.zeros(cells[2].shape, bool)
        self._exact.reshape(-1)[cell[beyond]] = True
        self.exact_cells = int(np.count_nonzero(beyond))
        """How many (cell, camera) pairs are evaluated exactly at every pixel."""
        self.step = s
        """View pixels between the nodes (``step``, halved while a cell's error is too large)."""
        shape = self.buffer_shape(plan.width, plan.height, s)
        buffer = self.buffers.maps
        if buffer is None or buffer.shape != shape:
            buffer = self.buffers.maps = np.empty(shape, np.float32)
        self.buffer = buffer
        h0 = s // 2
        self.map_x = buffer[0, h0:h0 + plan.height, h0:h0 + plan.width]
        """View pixel -> mosaic column (float32, ``OUTSIDE`` where no camera is)."""
        self.map_y = buffer[1, h0:h0 + plan.height, h0:h0 + plan.width]
        """View pixel -> mosaic row (float32)."""
        self._values, self._far = values, far
        self._fill(self._assemble(*cells))

    @staticmethod
    def buffer_shape(width: int, height: int, step: int) -> Tuple[int, int, int]:
        """Return the shape of the resized node grid (x and y) for a view and a step."""
        return (2, (-(-height // step) + 1) * step, (-(-width // step) + 1) * step)

    def _cells(self, s: int) -> Tuple[np.ndarray, ...]:
        """
        Return ``(first, last, hit, full)`` at step ``s``.

        Per camera (the plan's regions in order) and view row (padded to whole cells,
        the rows below the view as its last) its region's first and last column, the
        cells its region touches and those it fills.
        """
        plan = self.plan
        width, height, cams = plan.width, plan.height, self._cams
        nxc, nyc = -(-width // s), -(-height // s)
        first = np.full((len(cams), nyc * s), width, np.int32)
        last = np.full((len(cams), nyc * s), -1, np.int32)
        for c, i in enumerate(cams):
            y0, lo, hi = plan.regions[int(i)]
            first[c, y0:y0 + len(lo)] = lo
            last[c, y0:y0 + len(hi)] = hi
        first[:, height:] = first[:, height - 1:height]
        last[:, height:] = last[:, height - 1:height]
        fc, lc = first.reshape(len(cams), nyc, s), last.reshape(len(cams), nyc, s)
        left = np.arange(0, nxc * s, s, dtype=np.int32)
        right = np.minimum(left + (s - 1), width - 1)
        hit = (left <= lc.max(axis=2)[..., None]) & (right >= fc.min(axis=2)[..., None])
        full = (left >= fc.max(axis=2)[..., None]) & (right <= lc.min(axis=2)[..., None])
        return first, last, hit, full

    def _evaluate(self, projection: Any, rotations: np.ndarray, cx: float, cy: float, s: int,
                  hit: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
        """
        Return the cameras' nodes (mosaic pixels, ``(2, cameras, rows, columns)``) and far.

        Each camera is evaluated at the corners of the cells it touches; a node not
        evaluated, one the lens cannot take (behind the camera, past its validity
        limit) or one mapped beyond the gap around the camera's image holds :data:`FAR`
        (far: True). Sets :attr:`worst_px` from the cells' centres.
        """
        cams = self._cams
        cn, nyc, nxc = hit.shape
        ny, nx = nyc + 1, nxc + 1
        need = np.zeros((cn, ny, nx), bool)
        need[:, :-1, :-1] = hit
        need[:, 1:, :-1] |= hit
        need[:, :-1, 1:] |= hit
        need[:, 1:, 1:] |= hit
        tables = self.buffers.tables(s, cn, nyc, nxc, cx, cy)
        node = np.flatnonzero(need)  # flat (camera, row, column) of the nodes
        cell = np.flatnonzero(hit)  # flat (camera, row, column) of the cells
        count = node.size
        rays = np.empty((3, count + cell.size), np.float32)
        rays[0, :count] = tables['node_u'][node]
        rays[1, :count] = tables['node_v'][node]
        rays[0, count:] = tables['cell_u'][cell]
        rays[1, count:] = tables['cell_v'][cell]
        rays[2] = 1.0
        # nodes and cells are camera by camera: two runs of the cameras in order
        sizes = np.concatenate([np.diff(np.searchsorted(node, np.arange(cn + 1) * (ny * nx))),
                                np.diff(np.searchsorted(cell, np.arange(cn + 1) * (nyc * nxc)))])
        label, px, py, side = projection._evaluate_runs(rays, rotations, np.tile(cams, 2), sizes)
        bad = (side & 16) != 0
        # the bilinear interpolation at each cell's centre (its four corner nodes, all
        # evaluated) against the exact value, where the cell's corners and centre have
        # pixels
        corners = tables['cell_node'][cell] + self._corner_offsets(nx)[:, None]
        raw = np.empty(cn * ny * nx, np.float32)  # read at the evaluated nodes only
        error = np.zeros(cell.size, np.float32)
        for exact in (px, py):
            raw[node] = exact[:count]
            at = raw[corners]
            np.maximum(error, np.abs(0.25 * (at[0] + at[2] + at[1] + at[3]) - exact[count:]),
                       out=error)   # TL + BL + TR + BR: the order of the sums before
        invalid = np.empty(cn * ny * nx, bool)
        invalid[node] = bad[:count]
        error[bad[count:] | invalid[corners].any(axis=0)] = 0.0
        self.worst_px = float(error.max(initial=0.0))
        self._cell_error = (cell, error)  # per cell touched: flat index, error
        x, y, far_node = self._mosaic_pixels(projection, label[:count], px[:count],
                                             py[:count], bad[:count])
        values = np.full((2, cn, ny, nx), FAR, np.float32)
        values[0].reshape(-1)[node] = x
        values[1].reshape(-1)[node] = y
        far = np.ones(need.shape, bool)
        far.reshape(-1)[node] = far_node
        return values, far

    @staticmethod
    def _corner_offsets(nx: int) -> np.ndarray:
        """Return the flat offsets of a cell's corner nodes (TL, TR, BL, BR), ``nx`` per row."""
        return np.array([0, 1, nx, nx + 1], np.intp)

    def _mosaic_pixels(self, projection: Any, label: np.ndarray, x: np.ndarray,
                       y: np.ndarray, bad: np.ndarray) -> Tuple[np.ndarray, ...]:
        """
        Return camera pixels ``(x, y)`` of cameras ``label`` in the mosaic, and where far.

        Beyond the gap (less a tap) a pixel would read a neighbour's image: such a node is
        far out (:data:`FAR`), as one the lens cannot take (``bad``); the pixels of its
        cells lie beyond the frame by more than the bilinear taps reach (a cell spanning
        fewer camera pixels than the gap), black in the camera's own image as well.
        """
        reach = self._layout.gap - 2.0
        sizes = projection._sizes  # per camera (the few cameras, then gathered per pixel)
        high_x, high_y = sizes[:, 0] - 1.0 + reach, sizes[:, 1] - 1.0 + reach
        offsets = np.asarray(self._layout.offsets, np.float32)
        offset_x, offset_y = offsets[:, 0], offsets[:, 1]
        far = bad | (x < -reach) | (x > high_x[label]) | (y < -reach) | (y > high_y[label])
        return (np.where(far, FAR, x + offset_x[label]), np.where(far, FAR, y + offset_y[label]),
                far)

    def _assemble(self, first: np.ndarray, last: np.ndarray, hit: np.ndarray,
                  full: np.ndarray) -> Tuple[np.ndarray, ...]:
        """
        Decide the nodes' values (:attr:`nodes`) and the cells filled pixel by pixel.

        Returns those cells' map (:meth:`_by_pixel`), valid until the next pose's maps.
        """
        cn, nyc, nxc = hit.shape
        empty = cn  # the code of a cell no region touches
        count = hit.sum(axis=0)
        code = np.where(count > 0, -1, empty).astype(np.int16)  # -1: pixel by pixel
        pure = full & (count == 1)
        if self.exact_cells:
            pure &= ~self._exact.any(axis=0)
        pure_cells = np.flatnonzero(pure)  # flat (camera, row, column)
        pc = pure_cells // (nyc * nxc)
        code.reshape(-1)[pure_cells - pc * (nyc * nxc)] = pc
        owner = self._owners(code, empty)
        taken = np.flatnonzero((owner >= 0) & (owner < empty))  # flat (row, column)
        source = owner.reshape(-1)[taken].astype(np.intp) * owner.size + taken  # flat (c, b, a)
        self.nodes = np.full((2,) + owner.shape, OUTSIDE, np.float32)
        """The node grid :attr:`buffer` is resized from: x and y (mosaic pixels)."""
        for nodes, values in zip(self.nodes, self._values):
            nodes.reshape(-1)[taken] = values.reshape(-1)[source]
        self._used = np.zeros(self._far.shape, bool)  # the nodes the map interpolates
        self._used.reshape(-1)[source] = True
        fb, fa = np.divmod(np.flatnonzero(code < 0), nxc)
        return self._by_pixel(first, last, hit, fb, fa)

    @staticmethod
    def _owners(code: np.ndarray, empty: int) -> np.ndarray:
        """
        Return each node's owner: the camera (or ``empty``) of the cells that take it, or -1.

        A node that two kinds of cells would take (two cameras, or a camera and none)
        sends the cells around it pixel by pixel (``code`` -1, changed in place).
        """
        nyc, nxc = code.shape
        high = np.full((nyc + 2, nxc + 2), -1, np.int16)
        low = np.full((nyc + 2, nxc + 2), empty + 1, np.int16)
        high[1:-1, 1:-1] = code
        low[1:-1, 1:-1] = np.where(code >= 0, code, empty + 1)
        top = np.maximum(np.maximum(high[:-1, :-1], high[1:, :-1]),
                         np.maximum(high[:-1, 1:], high[1:, 1:]))
        bottom = np.minimum(np.minimum(low[:-1, :-1], low[1:, :-1]),
                            np.minimum(low[:-1, 1:], low[1:, 1:]))
        clash = (top >= 0) & (bottom != top)
        if not clash.any():
            return top
        # the cells around a clash go pixel by pixel: their other nodes lose a taker and
        # no node gains one, so no new clash arises
        code[clash[:-1, :-1] | clash[1:, :-1] | clash[:-1, 1:] | clash[1:, 1:]] = -1
        high[1:-1, 1:-1] = code
        return np.maximum(np.maximum(high[:-1, :-1], high[1:, :-1]),
                          np.maximum(high[:-1, 1:], high[1:, 1:]))

    def _by_pixel(self, first: np.ndarray, last: np.ndarray, hit: np.ndarray,
                  fb: np.ndarray, fa: np.ndarray) -> Tuple[np.ndarray, ...]:
        """
        Return the map over cells ``(fb, fa)``, pixel by pixel: ``(b, a, values, eb, ea)``.

        ``values`` ``(2, cells, s, s)`` are those of cells ``(b, a)``; cells ``(eb, ea)``
        (no region touches them) read ``OUTSIDE``. For each (cell, camera) pair the
        bilinear interpolation of the camera's corner nodes with the resize's weights
        (one product, pairs x 4 corners times 4 x pixels, by ``np.einsum`` in this
        thread: ``cv2.gemm`` on OpenCV 5 and ``np.matmul`` hand it to OpenBLAS's threads,
        whose second thread then spins on the other core, so a moving view's process
        took twice its thread's CPU, and on a loaded 2-core machine a call waited a
        median 3-15 ms for them, against 0.4 ms here), kept where the camera's region
        holds the pixel; the regions are disjoint, so each pixel takes the pair that
        holds it, ``OUTSIDE`` where none does.
        """
        s = self.step
        cn, nyc, nxc = hit.shape
        pk, pc = np.nonzero(hit[:, fb, fa].T)  # (cell, camera) pairs, by cell
        rank = np.arange(pk.size) - np.searchsorted(pk, pk)  # a cell's pairs: 0, 1, ...
        if rank.any():  # by rank: each cell's first pair, then the second ones, ...
            order = np.argsort(rank, kind='stable')
            pk, pc, rank = pk[order], pc[order], rank[order]
        ends = np.searchsorted(rank, np.arange(1, int(rank.max(initial=0)) + 2))
        cells = int(ends[0])
        b, a = fb[pk], fa[pk]
        spare = np.ones(fb.size, bool)
        spare[pk[:cells]] = False
        if not pk.size:
            return b, a, np.empty((2, 0, s, s), np.float32), fb[spare], fa[spare]
        corners = (pc * (nyc + 1) + b) * (nxc + 1) + a
        corners = corners[:, None] + self._corner_offsets(nxc + 1)  # (pairs, 4)
        self._used.reshape(-1)[corners] = True
        at = np.empty((2, pk.size, 4), np.float32)  # x/y, pair, corner
        for plane, values in zip(at, self._values):
            plane[...] = values.reshape(-1)[corners]
        inner = np.einsum('pk,kq->pq', at.reshape(-1, 4), _weights(s),
                          out=self.buffers.scratch(2 * pk.size, s * s)).reshape(2, pk.size, s * s)
        span = np.arange(s)
        exact = np.flatnonzero(self._exact[pc, b, a]) if self.exact_cells else ()
        if len(exact):  # the lens at every pixel of these pairs' cells
            projection, rotations, cx, cy = self._lens
            u = (a[exact, None, None] * s + span - cx).astype(np.float32)
            v = (b[exact, None, None] * s + span[:, None] - cy).astype(np.float32)
            rays = np.stack(np.broadcast_arrays(u, v, np.float32(1.0))).reshape(3, -1)
            label = np.repeat(self._cams[pc[exact]], s * s)
            _, x, y, side = projection._evaluate_soa(np.ascontiguousarray(rays), rotations,
                                                     only=label)
            x, y, _ = self._mosaic_pixels(projection, label, x, y, (side & 16) != 0)
            inner[:, exact] = np.stack([x, y]).reshape(2, len(exact), s * s)
        rows = (pc * (nyc * s) + b * s)[:, None] + span  # flat (camera, view row), (pairs, s)
        cols = (a[:, None] * s + span).astype(np.int32)[:, None, :]
        outside = ((first.reshape(-1)[rows][:, :, None] > cols) |
                   (cols > last.reshape(-1)[rows][:, :, None])).reshape(pk.size, s * s)
        values = inner[:, :cells]
        np.copyto(values, np.float32(OUTSIDE), where=outside[:cells])
        for r0, r1 in zip(ends[:-1], ends[1:]):  # a cell's further pairs (rarely two)
            place = np.searchsorted(pk[:cells], pk[r0:r1])
            held = ~outside[r0:r1]
            for plane, pairs in zip(values, inner[:, r0:r1]):
                more = plane[place]
                np.copyto(more, pairs, where=held)
                plane[place] = more
        return b[:cells], a[:cells], values.reshape(2, cells, s, s), fb[spare], fa[spare]

    def _fill(self, fix: Tuple[np.ndarray, ...]) -> None:
        """Resize the node grid into :attr:`buffer`, then write the cells of :meth:`_by_pixel`."""
        import cv2

        s, buffer = self.step, self.buffer
        nyc, nxc = self.nodes.shape[1] - 1, self.nodes.shape[2] - 1
        for plane, nodes in zip(buffer, self.nodes):
            cv2.resize(nodes, (plane.shape[1], plane.shape[0]), dst=plane,
                       interpolation=cv2.INTER_LINEAR)
        fb, fa, values, eb, ea = fix
        rs, cs = buffer.strides[1:]
        h0 = s // 2
        for plane, v in zip(buffer, values):  # the cells as (rows, columns, s, s)
            cells = np.lib.stride_tricks.as_strided(
                plane[h0:, h0:], (nyc, nxc, s, s), (s * rs, s * cs, rs, cs))
            cells[fb, fa] = v
            cells[eb, ea] = OUTSIDE

    def seen(self, rows: np.ndarray, columns: np.ndarray) -> np.ndarray:
        """
        Return which view pixels ``rows x columns`` read a camera's image (bool grid).

        Those mapped within a camera's frame, to half a pixel beyond its outermost pixel
        centres (within the map's tolerance of the exact lens). 96 x 54 pixels of a
        1280x720 view: 0.12 ms, 0.34 ms in the frame (the map cold in the caches), where
        evaluating the lens at them takes 1.0-1.4 ms, on every frame of a moving view.
        """
        x, y = self.map_x[np.ix_(rows, columns)], self.map_y[np.ix_(rows, columns)]
        seen = np.zeros(x.shape, bool)
        for (x0, y0), (w, h) in zip(self._layout.offsets, self._sizes):
            seen |= (x >= x0 - 0.5) & (x <= x0 + w - 0.5) & (y >= y0 - 0.5) & (y <= y0 + h - 0.5)
        return seen

    def full_map(self) -> np.ndarray:
        """Return the map as one ``(H, W, 2)`` float32 array (a copy of :attr:`map_x`, ``_y``)."""
        return np.stack([self.map_x, self.map_y], axis=-1)

    @property
    def rects(self) -> Dict[int, Rect]:
        """Return per camera the rectangle of its image the map reads (with the taps)."""
        if self._rects is None:
            self._rects = {}
            ok = np.flatnonzero(self._used & ~self._far)  # flat (camera, row, column)
            cn = len(self._cams)
            cam = ok // (self._far.size // max(cn, 1))
            starts = np.searchsorted(cam, np.arange(cn + 1))
            some = starts[:-1] < starts[1:]
            offsets = np.asarray(self._layout.offsets, np.float32)[self._cams]
            low = np.full((2, cn), np.inf, np.float32)
            high = np.full((2, cn), -np.inf, np.float32)
            for k, values in enumerate(self._values):
                local = values.reshape(-1)[ok] - offsets[cam, k]
                if local.size:
                    low[k, some] = np.minimum.reduceat(local, starts[:-1][some])
                    high[k, some] = np.maximum.reduceat(local, starts[:-1][some])
            for c, i in enumerate(int(k) for k in self._cams):
                w, h = self._sizes[i]
                if not np.isfinite(low[0, c]):
                    self._rects[i] = (0, 0, 0, 0)
                    continue
                x0, y0, x1, y1 = (int(math.floor(e))
                                  for e in (low[0, c], low[1, c], high[0, c], high[1, c]))
                self._rects[i] = (min(w, max(0, x0)), min(h, max(0, y0)),
                                  max(0, min(w, x1 + 2)), max(0, min(h, y1 + 2)))
        return self._rects

    def render(self, sources: CameraSources, mosaic: np.ndarray, version: Any,
               out: np.ndarray, canvas: np.ndarray) -> None:
        """
        Fill ``out`` from the cameras' images by one remap.

        ``canvas`` is ``out`` to remap the mosaic as it is, else a 4-channel buffer: the
        cameras' images are then read in 4 channels (``sources``) and the canvas is
        converted to ``out`` (:func:`four_channels`).
        """
        import cv2

        source, target = mosaic, out
        if canvas is not out:
            for i, rect in self.rects.items():
                sources.get(mosaic, i, rect, version)
            source, target = sources.image(mosaic), canvas
        cv2.remap(source, self.map_x, self.map_y, cv2.INTER_LINEAR, dst=target,
                  borderMode=cv2.BORDER_CONSTANT, borderValue=0)
        if canvas is not out:
            cv2.cvtColor(canvas, cv2.COLOR_BGRA2BGR, dst=out)
