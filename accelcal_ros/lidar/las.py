"""
LAS 1.4 / LAZ output of georeferenced clouds (laspy, LAZ through lazrs), streamed.

What is written (ASPRS LAS 1.4 R15):

- point data record format 6: x y z as int32 with scale 0.001 m (1 mm) and offsets at
  the survey (the first map point rounded to 1 km), so UTM magnitudes (6e6 m) keep 1 mm;
  ``gps_time``; ``intensity`` (the scan's value, rounded and clipped to 0..65535);
  ``return_number``/``number_of_returns`` (from a ``return`` field, else 1 of 1); the
  laser ring, when the scan has one, as an extra-bytes dimension ``ring`` (uint16);
- the CRS as OGC WKT (WKT 1, a WKT coordinate-system VLR, global-encoding WKT bit set):
  PDAL, QGIS and CloudCompare place the cloud without being told. Heights are WGS84
  ellipsoidal (no geoid), which the horizontal WKT cannot say: a text VLR
  ``accelcal_ros/1`` says it, with the time system;
- time: absolute Unix (ROS) stamps become Adjusted Standard GPS Time (GPS seconds minus
  1e9; global-encoding bit 0 set), with the leap seconds of :data:`LEAP_SECONDS`; a clock
  before the GPS epoch (a simulation or a relative clock) is written as it is, bit 0
  clear, and the VLR says "recording clock".

The file is written batch by batch into a temporary file that replaces the target only
when complete (:func:`accelcal_ros.fileio.atomic_output_path`): memory is bounded by one
batch (two while one is compressed), and a failed or interrupted run leaves no partial
output.
"""
import calendar
from concurrent.futures import Future, ThreadPoolExecutor
from contextlib import ExitStack
import os
from types import TracebackType
from typing import Any, List, Optional, Type

from accelcal_ros.errors import InputError
import numpy as np
from numpy.typing import ArrayLike

SCALE_M = 0.001
"""Coordinate resolution (m)."""

GPS_EPOCH_UNIX_S = 315964800.0
"""1980-01-06 00:00:00 UTC in Unix seconds."""

LEAP_SECONDS = tuple((float(calendar.timegm((y, m, 1, 0, 0, 0))), n) for n, (y, m) in enumerate(
    ((1981, 7), (1982, 7), (1983, 7), (1985, 7), (1988, 1), (1990, 1), (1991, 1), (1992, 7),
     (1993, 7), (1994, 7), (1996, 1), (1997, 7), (1999, 1), (2006, 1), (2009, 1), (2012, 7),
     (2015, 7), (2017, 1)), start=1))
"""``(Unix time the offset took effect, GPS - UTC seconds)``; 18 s since 2017-01-01."""


def is_unix_clock(times_s: ArrayLike) -> bool:
    """Return whether times are absolute Unix seconds (after the GPS epoch)."""
    t = np.asarray(times_s, dtype=float)
    return bool(t.size) and float(np.nanmin(t)) >= GPS_EPOCH_UNIX_S


def unix_to_adjusted_gps(unix_s: ArrayLike) -> np.ndarray:
    """Return Adjusted Standard GPS Time (GPS s - 1e9) of Unix (UTC) times."""
    t = np.asarray(unix_s, dtype=float)
    starts = np.array([s for s, _ in LEAP_SECONDS])
    offsets = np.concatenate([[0.0], [float(n) for _, n in LEAP_SECONDS]])
    leap = offsets[np.searchsorted(starts, t, side='right')]
    return t - GPS_EPOCH_UNIX_S + leap - 1e9


def adjusted_gps_to_unix(gps_s: ArrayLike) -> np.ndarray:
    """Inverse of :func:`unix_to_adjusted_gps` (outside a leap second itself)."""
    g = np.asarray(gps_s, dtype=float)
    first = g + 1e9 + GPS_EPOCH_UNIX_S
    return first - (unix_to_adjusted_gps(first) - g)


def is_las_path(path: Any) -> bool:
    """Return whether a path names a LAS or LAZ file (by extension)."""
    return os.path.splitext(os.fspath(path))[1].lower() in ('.las', '.laz')


class LasCloudWriter:
    """
    Stream georeferenced points into a LAS 1.4 / LAZ file (``with`` block, atomic).

    ``wkt`` is the horizontal CRS; ``origin_m`` a map point near the survey (offsets);
    ``unix_clock``: the point times are Unix seconds (converted to Adjusted Standard GPS
    Time) or another clock (written as is). ``ring``: whether the records carry it.
    Records are buffered up to ``flush_points`` and compressed by a writer thread while
    the caller prepares the next batch (lazrs compresses in parallel, without the GIL):
    memory holds at most two batches.
    """

    def __init__(self, path: Any, wkt: str, origin_m: ArrayLike, unix_clock: bool,
                 ring: bool = False, crs_name: str = '', flush_points: int = 1 << 20) -> None:
        self.path = os.fspath(path)
        self.wkt = wkt
        self.offset = np.round(np.asarray(origin_m, dtype=float).reshape(3) / 1000.0) * 1000.0
        self.unix_clock = unix_clock
        self.ring = ring
        self.crs_name = crs_name
        self.count = 0
        self.flush_points = flush_points
        self._stack: Optional[ExitStack] = None
        self._writer: Any = None
        self._header: Any = None
        self._buffer: List[np.ndarray] = []
        self._buffered = 0
        self._pending: Optional['Future[None]'] = None
        self._pool = ThreadPoolExecutor(max_workers=1)

    def _make_header(self) -> Any:
        import laspy
        from laspy.header import GpsTimeType
        from laspy.vlrs.known import WktCoordinateSystemVlr

        header = laspy.LasHeader(point_format=6, version='1.4')
        if self.ring:
            header.add_extra_dim(laspy.ExtraBytesParams(
                name='ring', type=np.uint16, description='laser ring, 0 = lowest beam'))
        header.scales = np.full(3, SCALE_M)
        header.offsets = self.offset
        header.vlrs.append(WktCoordinateSystemVlr(self.wkt))
        header.global_encoding.wkt = True
        header.global_encoding.gps_time_type = (GpsTimeType.STANDARD if self.unix_clock
                                                else GpsTimeType.WEEK_TIME)
        header.system_identifier = 'accelcal_ros georeference'
        header.generating_software = 'accelcal_ros (laspy)'
        clock = ('Adjusted Standard GPS Time (GPS s - 1e9) from the Unix/ROS stamps of the '
                 'recording' if self.unix_clock else 'the recording clock (s), not GPS time')
        note = (f'CRS {self.crs_name}; heights: WGS84 ellipsoidal (no geoid); gps_time: '
                f'{clock}')
        header.vlrs.append(laspy.VLR(user_id='accelcal_ros', record_id=1,
                                     description='georeference notes',
                                     record_data=note.encode('utf-8')))
        return header

    def __enter__(self) -> 'LasCloudWriter':
        """Open the temporary file and write the header."""
        import laspy
        from accelcal_ros.fileio import atomic_output_path

        self._header = self._make_header()
        stack = ExitStack()
        try:
            tmp = stack.enter_context(atomic_output_path(self.path))
            compress = self.path.lower().endswith('.laz')
            backend = laspy.LazBackend.LazrsParallel if compress else None
            self._writer = stack.enter_context(laspy.open(
                tmp, mode='w', header=self._header, do_compress=compress,
                laz_backend=backend))
        except BaseException:
            stack.close()
            raise
        self._stack = stack
        return self

    def write(self, xyz_m: ArrayLike, times_s: ArrayLike, intensity: Optional[ArrayLike] = None,
              ring: Optional[ArrayLike] = None, returns: Optional[ArrayLike] = None) -> None:
        """Append points: map ``(N, 3)`` m, times (s, the clock given), optional fields."""
        pts = np.asarray(xyz_m, dtype=np.float64).reshape(-1, 3)
        n = len(pts)
        if not n:
            return
        ints = np.round((pts - self.offset) / SCALE_M)
        if np.any(np.abs(ints) > 2**31 - 1):
            raise InputError(f'{self.path}: points lie more than 2147 km from the '
                             f'offset {self.offset.tolist()} m: wrong CRS or trajectory?')
        rec = np.zeros(n, dtype=self._header.point_format.dtype())
        rec['X'], rec['Y'], rec['Z'] = ints[:, 0], ints[:, 1], ints[:, 2]
        t = np.asarray(times_s, dtype=float).reshape(-1)
        rec['gps_time'] = unix_to_adjusted_gps(t) if self.unix_clock else t
        if intensity is not None:
            rec['intensity'] = np.clip(np.round(np.asarray(intensity, float)), 0, 65535)
        # format 6 bit field: return number (bits 0-3), number of returns (bits 4-7)
        r = (np.ones(n, np.uint8) if returns is None
             else np.clip(np.asarray(returns), 1, 15).astype(np.uint8))
        rec['bit_fields'] = r | (r << 4)
        if self.ring and ring is not None:
            rec['ring'] = np.asarray(ring).astype(np.uint16)
        self._buffer.append(rec)
        self._buffered += n
        self.count += n
        if self._buffered >= self.flush_points:
            self._flush()

    def _flush(self) -> None:
        """Hand the buffered records to the compressing thread (one batch in flight)."""
        import laspy

        if not self._buffer:
            return
        data = np.concatenate(self._buffer) if len(self._buffer) > 1 else self._buffer[0]
        self._buffer, self._buffered = [], 0
        self._wait()
        record = laspy.PackedPointRecord(data, self._header.point_format)
        self._pending = self._pool.submit(self._writer.write_points, record)

    def _wait(self) -> None:
        pending, self._pending = self._pending, None
        if pending is not None:
            pending.result()

    def __exit__(self, exc_type: Optional[Type[BaseException]],
                 exc: Optional[BaseException], tb: Optional[TracebackType]) -> None:
        """Finish the file (header counts and bounds) and put it in place, or discard it."""
        stack, self._stack = self._stack, None
        if stack is None:
            return
        try:
            if exc_type is None:
                self._flush()
                self._wait()
        except BaseException as error:
            exc_type, exc, tb = type(error), error, error.__traceback__
            raise
        finally:
            if exc_type is not None and self._pending is not None:
                self._pending.exception()       # let the thread finish; its error is moot
                self._pending = None
            self._pool.shutdown(wait=True)
            stack.__exit__(exc_type, exc, tb)
