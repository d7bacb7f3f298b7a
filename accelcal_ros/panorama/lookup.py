r"""
Lookup maps, fast: the coarse grid, cell classes and exact seams (the stitcher's rebuild).

Rays are projected into the rig by :mod:`.rig_projection` (the tilt, eq. 7; the camera
choice, eq. 6; the lens); :mod:`.maps` builds exact maps; this module builds the
same map fast.

Maps are expressed in the coordinates of a *mosaic*: all camera images side by side,
separated by black gaps (:class:`~.mosaic.MosaicLayout`), so a whole panorama frame is one
``cv2.remap`` of the mosaic. Pixel coordinates follow OpenCV (integers at pixel
centres). Bilinear interpolation treats everything outside a frame as black: a point
between the outermost pixel centres and one pixel beyond them fades linearly to black,
a point farther out is black (step 5); the gaps make that hold in the mosaic too.

Two builders give the same map:

- :meth:`~.maps.MapBuilder.build_exact` evaluates every pixel (about a second at 3600x2400).
- :meth:`LookupBuilder.build_fast` evaluates exactly a coarse grid of nodes every
  ``grid_step`` pixels and classifies each cell (:meth:`LookupBuilder.classify`) as
  *pure* -- the same camera at its corners, within the mosaic gap around that camera's
  frame, and a bilinear interpolation error, estimated from the nodes' second
  differences (next to a seam, from the stencil on the cell's side of it) or, where
  that fails, measured at the cell's centre and edge midpoints, within 3/4 of the
  tolerance (the centre of a quadratic is where its bilinear error peaks; the margin
  covers higher-order terms) --, *empty* (outside the frame on
  one side, or, across a seam, every camera present has a point farther out of its
  frame than a cell can extend) or *mixed*. Pure cells are interpolated bilinearly by
  one ``cv2.resize`` of the node map (a cell across a frame edge is pure: its outer part
  lands in the black gap), empty cells are set to "outside", mixed cells (seams between
  cameras, the panorama border) are refined by sub-blocks of a few pixels, classified
  the same way from their exactly evaluated corners and centre, and evaluated pixel by
  pixel only where a seam crosses a sub-block. Only rows some camera can see are
  evaluated (:meth:`LookupBuilder.seen_rows` bounds them beforehand from the frames'
  borders) and built.
  ``test/panorama/test_lookup.py`` measures the maximum error over every pixel against
  :meth:`~.maps.MapBuilder.build_exact`.
"""
import math
import time
from typing import Optional, Tuple, TYPE_CHECKING

from accelcal_ros.errors import InputError
from accelcal_ros.frames import DEFAULT_IMU_TO_CAMERA
from accelcal_ros.panorama.maps import MapBuilder
from accelcal_ros.panorama.mosaic import OUTSIDE
from accelcal_ros.panorama.rig_projection import _SIDE_INVALID, RigProjection
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from concurrent.futures import Future, ThreadPoolExecutor

    from accelcal_ros.camera.rig import Rig
    from accelcal_ros.panorama.projection import PanoramaGeometry

CENTRE_CHECK_FRACTION = 0.75
"""A pure cell's error at its centre and edge midpoints must be below this fraction of
``tolerance_px`` (the rest covers higher-order terms; the tests measure every pixel)."""


class LookupBuilder(MapBuilder):
    """
    Build panorama lookup maps for a rig, a panorama geometry and an ``imu_to_camera``.

    A map is a float32 array ``(height, width, 2)`` of mosaic coordinates ``(x, y)``;
    pixels no camera sees hold :data:`OUTSIDE`. ``grid_step`` (even, >= 4) is the cell
    size of the fast builder; it is reduced to the largest even divisor of the panorama
    width not above it when there is one (so that cells tile the width exactly).
    ``tolerance_px`` bounds the interpolation error of a pure cell (in camera pixels,
    checked at its centre).
    """

    resize_in_worker = True
    """Resize the node map in a worker thread while numpy does the other cells (a small
    map, e.g. a view's, is resized in place: handing it over costs more than it saves)."""

    def __init__(self, rig: 'Rig', geometry: 'PanoramaGeometry',
                 imu_to_camera: ArrayLike = DEFAULT_IMU_TO_CAMERA, grid_step: int = 20,
                 tolerance_px: float = 0.1) -> None:
        if isinstance(grid_step, bool) or int(grid_step) != grid_step or grid_step < 4:
            raise InputError(f'grid_step must be an integer >= 4, got {grid_step!r}')
        if not (math.isfinite(tolerance_px) and tolerance_px > 0):
            raise InputError(f'tolerance_px must be positive, got {tolerance_px!r}')
        RigProjection.__init__(self, rig, geometry, imu_to_camera)
        self.tolerance_px = float(tolerance_px)
        self.step = self._choose_step(int(grid_step), geometry.width)
        s = self.step
        # The gap around each image in the mosaic holds the outer part of a pure cell
        # straddling a frame edge; a point farther than a cell's extent outside a frame
        # proves the whole cell outside it; a ray past the distortion limit is that far
        # when the limit's margin exceeds the extent.
        self._far = self.cell_extent_px(s)
        gap = int(min(512, math.ceil(self._far) + 4))
        self._place_images(gap + gap % 2)
        self._margin = self.layout.gap - 2.0
        frame_gap_px = np.array([(math.sqrt(lim) - radius) * min(c.K[0, 0], c.K[1, 1])
                                 for c, (radius, lim) in zip(rig.cameras, self._radii)])
        self._invalid_is_far = frame_gap_px > self._far
        self._tiles_w = -(-geometry.width // s)
        self._tiles_h = -(-geometry.height // s)
        # Separable ray tables of pixels -s .. n s + s - 1 per axis: the cells at the
        # border reach half a cell beyond the panorama.
        self._set_ray_tables(s, (self._tiles_w + 1) * s, (self._tiles_h + 1) * s)
        # the same at pixel edges (continuous coordinate k - 1/2), for sub-block corners
        az_e = geometry.azimuth_rad(np.arange(-s, (self._tiles_w + 1) * s + 1) - 0.5)
        el_e = geometry.elevation_rad(np.arange(-s, (self._tiles_h + 1) * s + 1) - 0.5)
        self._sin_az_e = np.sin(az_e).astype(np.float32)
        self._cos_az_e = np.cos(az_e).astype(np.float32)
        self._sin_el_e = np.sin(el_e).astype(np.float32)
        self._cos_el_e = np.cos(el_e).astype(np.float32)
        half_step = s // 2
        self.sub_step = next((d for d in (5, 4, 3, 2) if half_step % d == 0), 0)
        # bilinear weights of a sub-block's pixels (row-major) on its corners 00, 01, 10, 11
        f = (np.arange(max(1, self.sub_step)) + 0.5) / max(1, self.sub_step)
        fy, fx = np.repeat(f, len(f)), np.tile(f, len(f))
        self._sub_weights = np.stack([(1 - fy) * (1 - fx), (1 - fy) * fx, fy * (1 - fx),
                                      fy * fx], axis=1).astype(np.float32)
        half = s // 2
        # Nodes (what cv2.resize interpolates) sit at pixel positions k*s + s/2 - 1/2,
        # k = 0..n-1; with the extra rows/columns at k = -1 and k = n they bound n + 1
        # cells per axis: cell b covers pixels [b*s - s/2, b*s + s/2), centre b*s - 1/2.
        node_u = np.arange(-1, self._tiles_w + 1) * s + half - 0.5
        node_v = np.arange(-1, self._tiles_h + 1) * s + half - 0.5
        centre_u = np.arange(self._tiles_w + 1) * s - 0.5
        centre_v = np.arange(self._tiles_h + 1) * s - 0.5
        self._node_rays = geometry.rays(node_u[None, :], node_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        self._centre_rays = geometry.rays(centre_u[None, :], centre_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        # midpoints of the horizontal and of the vertical cell edges
        self._hmid_rays = geometry.rays(centre_u[None, :], node_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        self._vmid_rays = geometry.rays(node_u[None, :], centre_v[:, None]).reshape(
            -1, 3).astype(np.float32)
        self._node_soa = np.ascontiguousarray(self._node_rays.T)
        self._centre_soa = np.ascontiguousarray(self._centre_rays.T)
        self._hmid_soa = np.ascontiguousarray(self._hmid_rays.T)
        self._vmid_soa = np.ascontiguousarray(self._vmid_rays.T)
        self._buffer: Optional[np.ndarray] = None
        self._resize_pool: Optional['ThreadPoolExecutor'] = None
        self.band = (0, geometry.height)
        self.last_stats = {}

    @staticmethod
    def _choose_step(step, width):
        step -= step % 2
        for s in range(step, 3, -2):
            if width % s == 0:
                return s
        return step

    # -- builders -------------------------------------------------------------------------
    def classify(self, q: np.ndarray, node_rows: Optional[Tuple[int, int]] = None
                 ) -> Tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """
        Classify the cells from the exact values at the nodes (and, where needed, more).

        Returns ``(node_map, empty, exact, pure)``: ``node_map`` ``(n_h, n_w, 2)`` holds
        the nodes' mosaic coordinates (what pure cells interpolate); the masks are per
        cell. Most cells are decided from the nodes alone: the same camera at the 4
        corners, all valid and within the gap around its frame, and the bilinear error
        estimated from the second differences at the corners, ``(|d2_u| + |d2_v|) / 8``
        (the error at the centre of a quadratic; where a corner's three-node stencil
        crosses a seam, the next stencil along, which holds that corner and so lies on
        its camera's side), within 3/4 of the tolerance -> pure; every camera present
        with a corner farther out than a cell
        reaches, or all corners outside on one side by more than a pixel -> empty. The
        other cells (seams, frame edges, the border) get their centre and edge midpoints
        evaluated: pure if the same camera is at all nine points, all near, with the
        bilinear error at the centre and midpoints within 3/4 of the tolerance.

        ``node_rows = (k0, k1)`` restricts the work to node rows ``k0 .. k1 - 1`` (at
        least 3): the arrays returned then cover those nodes and the cells between them
        (cell row ``j`` is the grid's ``k0 + j``). The first and last of those cell rows
        lack the nodes beyond them for the second differences and are decided the slow
        way.
        """
        tw = self._tiles_w
        k0, k1 = (0, self._tiles_h + 2) if node_rows is None else node_rows
        th = k1 - k0 - 2
        if th < 1:
            raise ValueError(f'node_rows {node_rows!r}: need at least 3 node rows')
        shape_n, shape_c = (th + 2, tw + 2), (th + 1, tw + 1)
        n_label, n_x, n_y, n_side = (a.reshape(shape_n) for a in self.evaluate_parallel(
            self._node_soa[:, k0 * (tw + 2):k1 * (tw + 2)], q))
        size = self._sizes[n_label]
        m = self._margin
        valid = (n_side & _SIDE_INVALID) == 0
        dist = np.maximum(np.maximum(-1.0 - n_x, n_x - size[..., 0]),
                          np.maximum(-1.0 - n_y, n_y - size[..., 1]))
        near = valid & (dist <= m - 1.0)
        node_map = np.stack([n_x + self._offsets[n_label, 0],
                             n_y + self._offsets[n_label, 1]], axis=-1)
        top, bottom, left, right = slice(0, -1), slice(1, None), slice(0, -1), slice(1, None)
        corners = [(top, left), (top, right), (bottom, left), (bottom, right)]
        limit = CENTRE_CHECK_FRACTION * self.tolerance_px
        # -- quick decisions from the nodes ----------------------------------------------
        same4 = np.ones(shape_c, bool)
        near4 = np.ones(shape_c, bool)
        common_side = np.full(shape_c, 255, np.uint8)
        min_dist = np.full(shape_c, np.inf, np.float32)
        c_label0 = n_label[top, left]
        for rs, cs in corners:
            same4 &= n_label[rs, cs] == c_label0
            near4 &= near[rs, cs]
            common_side &= n_side[rs, cs]
            min_dist = np.minimum(min_dist, np.where(valid[rs, cs], dist[rs, cs], np.inf))
        # second differences along u (rows of nodes) and v, with their label checks
        smooth = valid[:, 1:-1] & valid[:, :-2] & valid[:, 2:] \
            & (n_label[:, :-2] == n_label[:, 1:-1]) & (n_label[:, 2:] == n_label[:, 1:-1])
        d2u = np.maximum(np.abs(n_x[:, :-2] - 2 * n_x[:, 1:-1] + n_x[:, 2:]),
                         np.abs(n_y[:, :-2] - 2 * n_y[:, 1:-1] + n_y[:, 2:]))
        d2u = np.where(smooth, d2u, np.inf)  # (th + 2, tw): nodes columns 1..tw
        smooth = valid[1:-1] & valid[:-2] & valid[2:] \
            & (n_label[:-2] == n_label[1:-1]) & (n_label[2:] == n_label[1:-1])
        d2v = np.maximum(np.abs(n_x[:-2] - 2 * n_x[1:-1] + n_x[2:]),
                         np.abs(n_y[:-2] - 2 * n_y[1:-1] + n_y[2:]))
        d2v = np.where(smooth, d2v, np.inf)  # (th, tw + 2): node rows 1..th
        # Next to a seam or an invalid node, a node's three-point stencil fails; the
        # stencil one node further on (same camera, same curvature to first order)
        # stands in, so that only cells a seam crosses need the slow path.
        d2u = self._fill_from_neighbours(d2u, axis=1)
        d2v = self._fill_from_neighbours(d2v, axis=0)
        estimate = np.full(shape_c, np.inf, np.float32)
        inner = (slice(1, -1), slice(1, -1))  # cells whose 4x4 stencil exists
        est = np.zeros((th - 1, tw - 1), np.float32)
        for di in (0, 1):
            for dj in (0, 1):
                du = d2u[1 + di:th + di, dj:tw - 1 + dj]
                dv = d2v[di:th - 1 + di, 1 + dj:tw + dj]
                est = np.maximum(est, (du + dv) / 8.0)
        estimate[inner] = est
        quick_pure = same4 & near4 & (estimate <= limit)
        n_far = self._far_outside(n_label, n_x, n_y, n_side)
        covered = self._witnessed([n_label[rs, cs] for rs, cs in corners],
                                  [n_far[rs, cs] for rs, cs in corners], shape_c)
        quick_empty = ~quick_pure & (covered | (same4 & ((common_side & 15) != 0)
                                                & (min_dist >= 1.0)))
        fallback = ~(quick_pure | quick_empty)
        # -- the other cells (few): centre and edge midpoints, as vectors ---------------
        f_idx = np.flatnonzero(fallback)
        pure = quick_pure.copy()
        empty = quick_empty.copy()
        if f_idx.size:
            fa, fb = np.divmod(f_idx, tw + 1)
            corner_ids = [(fa + di, fb + dj) for di in (0, 1) for dj in (0, 1)]
            k_label = [n_label[ij] for ij in corner_ids]
            k_x = [n_x[ij] for ij in corner_ids]
            k_y = [n_y[ij] for ij in corner_ids]
            c_label, c_x, c_y, c_side = self.evaluate_parallel(
                self._centre_soa[:, f_idx + k0 * (tw + 1)], q)
            same = np.ones(f_idx.size, bool)
            all_near = (c_side & _SIDE_INVALID) == 0
            common5 = c_side.copy()
            all_invalid = c_side == _SIDE_INVALID
            for ij, la in zip(corner_ids, k_label):
                same &= la == c_label
                all_near &= near[ij]
                common5 &= n_side[ij]
                all_invalid &= n_side[ij] == _SIDE_INVALID
            error = np.maximum(np.abs(0.25 * sum(k_x) - c_x), np.abs(0.25 * sum(k_y) - c_y))
            candidate = same & all_near & (error <= limit)
            same5 = same.copy()
            cand = np.flatnonzero(candidate)
            if cand.size:
                ca, cb = fa[cand], fb[cand]
                # midpoints: top, bottom (horizontal edges), left, right (vertical edges)
                h_top = (ca + k0) * (tw + 1) + cb
                h_bottom = (ca + k0 + 1) * (tw + 1) + cb
                v_left = (ca + k0) * (tw + 2) + cb
                v_right = (ca + k0) * (tw + 2) + cb + 1
                rays = np.concatenate([self._hmid_soa[:, h_top], self._hmid_soa[:, h_bottom],
                                       self._vmid_soa[:, v_left], self._vmid_soa[:, v_right]],
                                      axis=1)
                m_label, m_x, m_y, m_side = (a.reshape(4, -1) for a in
                                             self.evaluate_parallel(rays, q))
                pairs = [(0, 1), (2, 3), (0, 2), (1, 3)]  # corner indices of each edge
                ok = np.ones(cand.size, bool)
                err = error[cand]
                for e, (ka, kb) in enumerate(pairs):
                    ok &= (m_label[e] == c_label[cand]) & ((m_side[e] & _SIDE_INVALID) == 0)
                    err = np.maximum(err, np.abs(0.5 * (k_x[ka][cand] + k_x[kb][cand])
                                                 - m_x[e]))
                    err = np.maximum(err, np.abs(0.5 * (k_y[ka][cand] + k_y[kb][cand])
                                                 - m_y[e]))
                candidate[cand] = ok & (err <= limit)
            pure.reshape(-1)[f_idx] = candidate
            # empty: the same camera at all five points, all outside its frame on one
            # side; or every camera present is witnessed far outside.
            c_far = self._far_outside(c_label, c_x, c_y, c_side)
            covered5 = self._witnessed(
                [c_label] + k_label, [c_far] + [n_far[ij] for ij in corner_ids],
                (f_idx.size,))
            slow_empty = ~candidate & ((same5 & (((common5 & 15) != 0) | all_invalid))
                                       | covered5)
            empty.reshape(-1)[f_idx] = slow_empty
        exact = ~empty & ~pure
        self.last_classes = {'quick_pure': int(quick_pure.sum()),
                             'quick_empty': int(quick_empty.sum()),
                             'fallback': int(fallback.sum())}
        return node_map, empty, exact, pure

    @staticmethod
    def _fill_from_neighbours(d2, axis):
        """Replace infinite second differences by the larger finite neighbour along ``axis``."""
        d = d2 if axis == 1 else d2.T
        finite = np.where(np.isfinite(d), d, -np.inf)
        neighbour = np.full_like(d, -np.inf)
        neighbour[:, 1:] = finite[:, :-1]
        np.maximum(neighbour[:, :-1], finite[:, 1:], out=neighbour[:, :-1])
        filled = np.where(np.isfinite(d), d, neighbour)
        filled[filled == -np.inf] = np.inf
        return filled if axis == 1 else filled.T

    def _witnessed(self, labels, fars, shape):
        """Return True where every camera present among the points has a far point."""
        if len(self.rig) <= 64:
            present = np.zeros(shape, np.uint64)
            witnessed = np.zeros(shape, np.uint64)
            for la, fa in zip(labels, fars):
                bit = np.left_shift(np.uint64(1), np.maximum(la, 0).astype(np.uint64))
                present |= bit
                witnessed |= bit * fa.astype(np.uint64)
            return (present & ~witnessed) == 0
        covered = np.ones(shape, bool)
        for la in labels:
            witness = np.zeros(shape, bool)
            for lb, fb in zip(labels, fars):
                witness |= (lb == la) & fb
            covered &= witness
        return covered

    def _far_outside(self, label, x, y, side):
        """Return True where a point is farther outside its camera's frame than a cell spans."""
        size = self._sizes[label]
        dist = np.maximum(np.maximum(-1.0 - x, x - size[..., 0]),
                          np.maximum(-1.0 - y, y - size[..., 1]))
        invalid = (side & _SIDE_INVALID) != 0
        return np.where(invalid, self._invalid_is_far[label], dist >= self._far)

    def build_fast(self, roll: float, pitch: float) -> np.ndarray:
        """
        Return the map from the coarse grid, interpolation, and exact mixed cells.

        The returned array is a view of a buffer owned by the builder (rows padded by one
        cell on each side, so not contiguous) and is overwritten by the next call. Only
        the rows in :attr:`band` (``(first, last + 1)``, the rows some camera sees) are
        defined; the others are left as they were.
        """
        import cv2

        start = time.perf_counter()
        s, half = self.step, self.step // 2
        tw, th = self._tiles_w, self._tiles_h
        height, width = self.geometry.shape
        q = self.camera_rotations(roll, pitch)
        node_map, empty, exact, pure = self._classify_seen_rows(q)
        t_grid = time.perf_counter()
        # Buffer pixel (r, c) is panorama pixel (r - s, c - s): the nodes one cell beyond
        # the panorama (k = -1 and k = n) sit inside it, so cv2.resize interpolates the
        # half cells at the border as well, and every cell is a full s x s block.
        if self._buffer is None:
            self._buffer = np.empty(((th + 2) * s, (tw + 2) * s, 2), np.float32)
        buf = self._buffer
        panorama = buf[s:s + height, s:s + width]
        # Only the rows of cells that some camera sees are built (and later remapped).
        active_rows = np.nonzero((~empty).any(axis=1))[0]
        if active_rows.size == 0:
            self.band = (0, 0)
            self.last_stats = {'total_s': time.perf_counter() - start, 'exact_pixels': 0}
            return panorama
        a0, a1 = int(active_rows[0]), int(active_rows[-1])
        # Nodes whose four cells are all empty are set to "outside": cv2.resize then
        # fills the cells between such nodes by itself, and only the ring of empty cells
        # next to seen ones needs filling.
        empty_cells = int(empty.sum())
        padded = np.pad(empty, 1, constant_values=True)
        lonely = padded[:-1, :-1] & padded[1:, :-1] & padded[:-1, 1:] & padded[1:, 1:]
        node_map[lonely] = OUTSIDE
        done = lonely[:-1, :-1] & lonely[1:, :-1] & lonely[:-1, 1:] & lonely[1:, 1:]
        empty &= ~done
        empty[:a0] = empty[a1 + 1:] = False
        exact[:a0] = exact[a1 + 1:] = False
        self.band = (max(0, a0 * s - half), min(height, a1 * s + half))
        # node rows k0 - 1 .. k1 + 1 (node_map rows k0 .. k1 + 2) cover cell rows a0..a1
        k0, k1 = max(0, a0 - 2), min(th - 1, a1 + 1)
        coarse = node_map[k0:k1 + 3]
        # The resize (OpenCV, no GIL) runs while numpy computes the cells it cannot do;
        # those are written into the buffer once it is done.

        def resize() -> None:
            cv2.resize(coarse, ((tw + 2) * s, (k1 - k0 + 3) * s),
                       dst=buf[k0 * s:(k1 + 3) * s], interpolation=cv2.INTER_LINEAR)

        resized: Optional['Future[None]'] = None
        if not self.resize_in_worker:
            resize()
        else:
            if self._resize_pool is None:
                from concurrent.futures import ThreadPoolExecutor

                self._resize_pool = ThreadPoolExecutor(max_workers=1,
                                                       thread_name_prefix='lookup_resize')
            resized = self._resize_pool.submit(resize)
        # cell (a, b) covers panorama pixels [a s - s/2, a s + s/2) x [b s - s/2, ...)
        blocks = self._blocks(buf[half:half + (th + 1) * s, half:half + (tw + 1) * s],
                              th + 1, s, tw + 1, s)
        values: Optional[np.ndarray] = None
        count = 0
        if exact.any():
            by, bx = np.nonzero(exact)
            rows, cols = by * s - half, bx * s - half
            if self.sub_step:
                values, count = self._refine(rows, cols, s, s, q)
            else:
                values = self._exact_pixels(rows, cols, s, s, q)
                count = int(values.size // 2)
        t_values = time.perf_counter()
        if resized is not None:
            resized.result()
        t_resize = time.perf_counter()
        if empty.any():
            blocks[empty] = OUTSIDE
        if values is not None:
            blocks[exact] = values
        end = time.perf_counter()
        self.last_stats = {
            'total_s': end - start, 'grid_s': t_grid - start,
            'cells_s': t_values - t_grid, 'resize_wait_s': t_resize - t_values,
            'write_s': end - t_resize, 'exact_pixels': count, 'cells': int(pure.size),
            'pure_cells': int(pure.sum()), 'empty_cells': empty_cells, 'step': s}
        return panorama

    def _classify_seen_rows(self, q):
        """
        :meth:`classify` over the cell rows :meth:`seen_rows` leaves; the others are empty.

        Returns the full-size ``(node_map, empty, exact, pure)``.
        """
        s, half = self.step, self.step // 2
        tw, th = self._tiles_w, self._tiles_h
        node_map = np.full((th + 2, tw + 2, 2), OUTSIDE, np.float32)
        empty = np.ones((th + 1, tw + 1), bool)
        exact = np.zeros_like(empty)
        pure = np.zeros_like(empty)
        r0, r1 = self.seen_rows(q)
        if r1 <= r0:
            self.last_classes = {'quick_pure': 0, 'quick_empty': 0, 'fallback': 0}
            return node_map, empty, exact, pure
        # cell b covers rows [b s - s/2, b s + s/2); its second differences need the node
        # rows b - 1 .. b + 2, so one more node row on each side than the cells' corners
        c0, c1 = (r0 + half) // s, (r1 - 1 + half) // s
        k0, k1 = max(0, c0 - 1), min(th + 2, c1 + 3)
        if k1 - k0 < 3:
            k0, k1 = max(0, k1 - 3), max(0, k1 - 3) + 3
        part = self.classify(q, (k0, k1))
        node_map[k0:k1] = part[0]
        for full, local in zip((empty, exact, pure), part[1:]):
            full[k0:k1 - 1] = local
        return node_map, empty, exact, pure

    @staticmethod
    def _blocks(region, nby, bh, nbx, bw):
        """View ``(nby, nbx, bh, bw, 2)`` of a buffer region made of equal blocks."""
        blocks = region.reshape(nby, bh, nbx, bw, 2)
        if not np.shares_memory(blocks, region):  # pragma: no cover - numpy guarantees it
            raise RuntimeError('block view is not a view')
        return blocks.transpose(0, 2, 1, 3, 4)

    def _exact_pixels(self, row0, col0, bh, bw, q):
        """Exact map values ``(n, bh, bw, 2)`` of blocks starting at pixels row0, col0."""
        rows = row0[:, None] + np.arange(bh)[None, :]
        cols = col0[:, None] + np.arange(bw)[None, :]
        rays = self._rays_at(rows, cols, self._cos_el, self._sin_el, self._sin_az,
                             self._cos_az).reshape(3, -1)
        values = self.to_mosaic(*self.evaluate_parallel(rays, q))
        return values.reshape(len(row0), bh, bw, 2)

    def _refine(self, row0, col0, bh, bw, q):
        """
        Map values of mixed blocks by sub-blocks of :attr:`sub_step` pixels.

        The corners and centre of every sub-block are evaluated exactly; a sub-block with
        the same camera at all five, all within the gap around its frame and the bilinear
        error at the centre within 3/4 of the tolerance is interpolated; one outside its
        frame on one side at all five points by more than a pixel is empty; the others
        (where a seam crosses) are evaluated pixel by pixel. Returns ``(values, number of
        pixels evaluated exactly)``.
        """
        sub = self.sub_step
        n, ny, nx = len(row0), bh // sub, bw // sub
        corners = self._rays_of_sub_edges(row0, col0, ny, nx)
        centres = self._rays_of_sub_centres(row0, col0, ny, nx, edges=sub % 2 == 0)
        count_c = n * (ny + 1) * (nx + 1)
        label, x, y, side = self.evaluate_parallel(
            np.concatenate([corners.reshape(3, -1), centres.reshape(3, -1)], axis=1), q)
        size = self._sizes[label]
        dist = np.maximum(np.maximum(-1.0 - x, x - size[:, 0]),
                          np.maximum(-1.0 - y, y - size[:, 1]))
        valid = (side & _SIDE_INVALID) == 0
        near = valid & (dist <= self._margin - 1.0)
        mx = x + self._offsets[label, 0]
        my = y + self._offsets[label, 1]
        shape_k, shape_s = (n, ny + 1, nx + 1), (n, ny, nx)
        k_label, k_near, k_side = (a[:count_c].reshape(shape_k) for a in (label, near, side))
        k_dist = np.where(valid, dist, np.inf)[:count_c].reshape(shape_k)
        k_mx, k_my = mx[:count_c].reshape(shape_k), my[:count_c].reshape(shape_k)
        s_label, s_near, s_side = (a[count_c:].reshape(shape_s) for a in (label, near, side))
        s_mx, s_my = mx[count_c:].reshape(shape_s), my[count_c:].reshape(shape_s)
        s_dist = np.where(valid, dist, np.inf)[count_c:].reshape(shape_s)
        top, bottom = slice(None, -1), slice(1, None)
        corner_sl = [(top, top), (top, bottom), (bottom, top), (bottom, bottom)]
        same, all_near = np.ones(shape_s, bool), s_near.copy()
        common = s_side.copy()
        min_dist = s_dist.copy()
        for rs, cs in corner_sl:
            same &= k_label[:, rs, cs] == s_label
            all_near &= k_near[:, rs, cs]
            common &= k_side[:, rs, cs]
            min_dist = np.minimum(min_dist, k_dist[:, rs, cs])
        c00, c01, c10, c11 = ([k_mx[:, rs, cs], k_my[:, rs, cs]] for rs, cs in corner_sl)
        error = np.maximum(np.abs(0.25 * (c00[0] + c01[0] + c10[0] + c11[0]) - s_mx),
                           np.abs(0.25 * (c00[1] + c01[1] + c10[1] + c11[1]) - s_my))
        pure = same & all_near & (error <= CENTRE_CHECK_FRACTION * self.tolerance_px)
        empty = same & ~pure & ((common & 15) != 0) & (min_dist >= 1.0)
        # bilinear interpolation of the pure sub-blocks: the fixed weights (sub * sub, 4)
        # times the four corners (4, 2) of each
        values = np.empty((n, ny, sub, nx, sub, 2), np.float32)
        view = values.transpose(0, 1, 3, 2, 4, 5)  # (n, ny, nx, sub, sub, 2)
        if pure.any():
            k = np.stack([k_mx, k_my], axis=-1)  # (n, ny+1, nx+1, 2)
            corners4 = np.stack([k[:, rs, cs][pure] for rs, cs in corner_sl], axis=1)
            view[pure] = np.matmul(self._sub_weights, corners4).reshape(-1, sub, sub, 2)
        if empty.any():
            view[empty] = OUTSIDE
        rest = ~pure & ~empty
        count = 0
        if rest.any():
            bi, byy, bxx = np.nonzero(rest)
            exact = self._exact_pixels(row0[bi] + byy * sub, col0[bi] + bxx * sub, sub, sub, q)
            view[rest] = exact
            count = int(exact.size // 2)
        return values.reshape(n, bh, bw, 2), count

    def _rays_of_sub_edges(self, row0, col0, ny, nx):
        """Rays ``(3, n, ny + 1, nx + 1)`` at the corners of the sub-blocks (pixel edges)."""
        sub = self.sub_step
        rows = row0[:, None] + sub * np.arange(ny + 1)[None, :]
        cols = col0[:, None] + sub * np.arange(nx + 1)[None, :]
        return self._rays_at(rows, cols, self._cos_el_e, self._sin_el_e, self._sin_az_e,
                             self._cos_az_e)

    def _rays_of_sub_centres(self, row0, col0, ny, nx, edges):
        """Rays ``(3, n, ny, nx)`` at the centres of the sub-blocks."""
        sub = self.sub_step
        offset = sub // 2
        rows = row0[:, None] + sub * np.arange(ny)[None, :] + offset
        cols = col0[:, None] + sub * np.arange(nx)[None, :] + offset
        if edges:
            return self._rays_at(rows, cols, self._cos_el_e, self._sin_el_e, self._sin_az_e,
                                 self._cos_az_e)
        return self._rays_at(rows, cols, self._cos_el, self._sin_el, self._sin_az,
                             self._cos_az)

    def _rays_at(self, rows, cols, cos_el, sin_el, sin_az, cos_az):
        """Rays ``(3, n, len_rows, len_cols)`` from per-block pixel rows and columns."""
        rows, cols = rows + self._pad, cols + self._pad
        ce = cos_el[rows][:, :, None]
        rays = np.empty((3,) + rows.shape + (cols.shape[1],), np.float32)
        np.multiply(ce, sin_az[cols][:, None, :], out=rays[0])
        rays[1] = -sin_el[rows][:, :, None]
        np.multiply(ce, cos_az[cols][:, None, :], out=rays[2])
        return rays
