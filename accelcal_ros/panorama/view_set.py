"""
Several named levelled views of one rig, sharing one mosaic (pure; the node and the server use it).

Each frame set is copied once into a :class:`~.view.ViewMosaic`; every view renders from
it with its own lookup (:class:`~.view.LevelledView`). Names are ROS name tokens (they
become topics ``roi/<name>/image``): a letter, then letters, digits and single
underscores, at most :data:`MAX_NAME_LENGTH` characters. At most ``max_views`` views
exist at once; one more is refused with the cap in the message and the others keep
working.

Threads: every method is thread-safe, and views render at once. :meth:`ViewSet.drawing`
renders one view while the frame set and that view hold still: many views draw together
(OpenCV's remap and the JPEG encoder release the GIL: one thread per browser tab),
:meth:`ViewSet.set_frame` waits until the frames being drawn are done and then goes
before any newer drawing (:class:`FrameLock`), and :meth:`ViewSet.set_pose` never waits
for a drawing: a pose given while its view is drawn is taken at the view's next frame
(:meth:`ViewSet.pose` returns it meanwhile). Locks, outermost first: the frame lock, a
view's own lock, the set's :attr:`ViewSet.lock` (held briefly, waiting for nothing).
One lock for everything drew the views one after another: on 2 cores beside the
``stitcher``, 4 still 1280x720 views with their JPEGs reached 16-22 frame sets/s, drawn
at once 28-30 (``benchmarks/bench_view.py``, OpenCV 4.6; ``docs/roi.md``).

Parameter form of a view (``roi_views`` of the node): ``NAME`` or
``NAME:AZIMUTH,ELEVATION,FOV_H`` in degrees, e.g. ``front:0,0,60``.
"""
from contextlib import contextmanager
import re
import threading
from typing import Any, Dict, Iterable, Iterator, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError, listed
from accelcal_ros.panorama.view import LevelledView, ViewMosaic
from accelcal_ros.panorama.view_grid import CameraSources
from accelcal_ros.panorama.view_pose import check_view_size, ViewPose
from accelcal_ros.panorama.view_warp import CameraPlanes
import numpy as np
from numpy.typing import ArrayLike

MAX_NAME_LENGTH = 48
"""Longest view name (it becomes part of two topic names)."""
DEFAULT_MAX_VIEWS = 8
"""Default cap on the number of views at once."""
_NAME = re.compile(r'[A-Za-z][A-Za-z0-9]*(_[A-Za-z0-9]+)*\Z')


class NoSuchView(InputError):
    """There is no view of that name (never was, or removed, perhaps while drawing)."""

    def __init__(self, name: str) -> None:
        super().__init__(f'no view named {name!r}')
        self.name = name


def check_view_name(name: Any) -> str:
    """Return ``name`` if it is a valid ROS name token, else raise :class:`InputError`."""
    if not isinstance(name, str) or not name:
        raise InputError(f'view name must be a non-empty string, got {name!r}')
    if len(name) > MAX_NAME_LENGTH or not _NAME.match(name):
        raise InputError(f'view name {name!r} is not a valid topic name token (a letter, '
                         'then letters, digits and single underscores, at most '
                         f'{MAX_NAME_LENGTH} characters)')
    return name


def repeated_names_reason(names: List[str]) -> Optional[str]:
    """Return why ``names`` cannot all be views (a name listed twice, named once), or None."""
    from collections import Counter

    repeated = sorted(n for n, count in Counter(names).items() if count > 1)
    if not repeated:
        return None
    return f'a view name is listed twice: {listed(repeated)}'


def parse_view_entry(entry: str) -> Tuple[str, Optional[ViewPose]]:
    """Return ``(name, pose or None)`` of ``NAME`` or ``NAME:AZ,EL,FOV`` (degrees)."""
    name, sep, rest = str(entry).partition(':')
    name = check_view_name(name.strip())
    if not sep:
        return name, None
    parts = rest.split(',')
    if len(parts) != 3:
        raise InputError(f'view {entry!r}: expected NAME:AZIMUTH,ELEVATION,FOV_H (degrees)')
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise InputError(f'view {entry!r}: azimuth, elevation and fov_h must be numbers '
                         '(degrees)') from None
    try:
        return name, ViewPose.from_degrees(*values)
    except InputError as exc:
        raise InputError(f'view {name!r}: {exc}') from None


class FrameLock:
    """
    Many drawings of a frame set at once, or one change of it (a phase-fair RW lock).

    :meth:`reading` is shared, :meth:`writing` exclusive. A waiting writer goes before any
    reader that comes after it (a stream of drawings cannot hold a new frame set off), and
    the readers that waited through a write go before the next writer (a stream of frame
    sets cannot hold the drawings off). Not re-entrant: a thread holding either side must
    not ask again.
    """

    def __init__(self) -> None:
        self._cond = threading.Condition(threading.Lock())
        self._readers = 0
        self._writing = False
        self._writers_waiting = 0
        self._readers_waiting = 0
        self._owed = 0   # readers that waited through the last write, not yet in
        self._writes = 0

    @contextmanager
    def reading(self) -> Iterator[None]:
        """Hold the frame set still (shared with other readers)."""
        with self._cond:
            arrived = self._writes
            self._readers_waiting += 1
            try:
                while self._writing or (self._writers_waiting and arrived == self._writes):
                    self._cond.wait()
            finally:
                self._readers_waiting -= 1
            if arrived != self._writes and self._owed:
                self._owed -= 1
                if not self._owed:
                    self._cond.notify_all()
            self._readers += 1
        try:
            yield
        finally:
            with self._cond:
                self._readers -= 1
                if not self._readers:
                    self._cond.notify_all()

    @contextmanager
    def writing(self) -> Iterator[None]:
        """Change the frame set (alone: after the readers inside and those owed a turn)."""
        with self._cond:
            self._writers_waiting += 1
            try:
                while self._writing or self._readers or self._owed:
                    self._cond.wait()
            finally:
                self._writers_waiting -= 1
            self._writing = True
        try:
            yield
        finally:
            with self._cond:
                self._writing = False
                self._writes += 1
                self._owed = self._readers_waiting
                self._cond.notify_all()


class ViewSet:
    """
    Named :class:`~.view.LevelledView` objects over one shared :class:`~.view.ViewMosaic`.

    ``width``/``height`` are the size of views added without one; ``imu_to_camera``
    defaults to the rig file's.
    """

    def __init__(self, rig: Any, imu_to_camera: Optional[ArrayLike] = None,
                 channels: int = 3, max_views: int = DEFAULT_MAX_VIEWS, width: int = 1280,
                 height: int = 720, grid_step: int = 16,
                 rebuild_threshold_deg: float = 0.005) -> None:
        if isinstance(max_views, bool) or not 1 <= int(max_views) <= 256:
            raise InputError(f'max_views must be in [1, 256], got {max_views!r}')
        self.rig = rig
        self.imu_to_camera = imu_to_camera
        self.mosaic = ViewMosaic(rig, channels)
        self.max_views = int(max_views)
        self.size = check_view_size(width, height)
        self.grid_step = grid_step
        self.rebuild_threshold_deg = rebuild_threshold_deg
        self.views: Dict[str, LevelledView] = {}
        self.planes: Optional[CameraPlanes] = None  # shared by the views (view_warp)
        self.sources: Optional[CameraSources] = None  # shared by the views (view_grid)
        self._drawn: Dict[Any, LevelledView] = {}  # frames drawn from this frame set
        self._drawn_version: Any = None
        self.shared_frames = 0
        self.attitude: Optional[Tuple[float, float]] = None
        self.stamp_s: Optional[float] = None
        self.lock = threading.RLock()
        """The set's own state (views, poses waiting, shared frames): held briefly."""
        self.frame_lock = FrameLock()
        """The mosaic and the attitude: shared by drawings, exclusive for a new frame set."""
        self._view_locks: Dict[str, threading.Lock] = {}
        self._poses_waiting: Dict[str, ViewPose] = {}

    def names(self) -> List[str]:
        """Return the view names in the order they were added."""
        with self.lock:
            return list(self.views)

    def add(self, name: str, pose: Optional[ViewPose] = None, width: Optional[int] = None,
            height: Optional[int] = None) -> LevelledView:
        """Add a view (InputError: bad name, taken, bad size, or the cap reached)."""
        name = check_view_name(name)
        size = check_view_size(width or self.size[0], height or self.size[1])
        with self.lock:
            if name in self.views:
                raise InputError(f'view {name!r} exists already')
            if len(self.views) >= self.max_views:
                raise InputError(f'too many views: at most {self.max_views} at once '
                                 f'({", ".join(self.views)}); remove one first')
            view = LevelledView(self.rig, self.mosaic.layout, size[0], size[1], pose,
                                self.imu_to_camera, self.grid_step,
                                rebuild_threshold_deg=self.rebuild_threshold_deg,
                                planes=self.planes, sources=self.sources)
            self.planes = view.shared_planes()
            self.sources = view.shared_sources()
            if self.attitude is not None:
                view.set_attitude(*self.attitude)
            self.views[name] = view
            self._view_locks[name] = threading.Lock()
            return view

    def remove(self, name: str) -> None:
        """Remove a view (:class:`NoSuchView` if there is none of that name)."""
        with self.lock:
            if self.views.pop(name, None) is None:
                raise NoSuchView(name)
            self._forget(name)

    def _forget(self, name: str) -> None:
        """Drop a removed view's lock and waiting pose (a drawing in progress finishes)."""
        self._view_locks.pop(name, None)
        self._poses_waiting.pop(name, None)

    def set_pose(self, name: str, pose: ViewPose) -> None:
        """
        Point view ``name`` (the view keeps its last pose when this raises).

        Never waits for a drawing: while the view is being drawn the pose waits for its
        next frame (:meth:`pose` returns it meanwhile).
        """
        if not isinstance(pose, ViewPose):
            raise InputError(f'expected a ViewPose, got {type(pose).__name__}')
        with self.lock:
            view = self.views.get(name)
            if view is None:
                raise NoSuchView(name)
            lock = self._view_locks[name]
            if lock.acquire(blocking=False):
                try:
                    view.set_pose(pose)
                    self._poses_waiting.pop(name, None)
                finally:
                    lock.release()
            else:
                self._poses_waiting[name] = pose

    def pose(self, name: str) -> ViewPose:
        """Return the newest pose of view ``name`` (one waiting for its next frame, if any)."""
        with self.lock:
            view = self.views.get(name)
            if view is None:
                raise NoSuchView(name)
            return self._poses_waiting.get(name, view.pose)

    def apply_entries(self, entries: Iterable[str]) -> Tuple[List[str], List[str]]:
        """
        Make the views those of ``entries`` (``NAME`` or ``NAME:AZ,EL,FOV``): all or nothing.

        New names are added, missing ones removed, listed poses applied; every entry is
        checked before anything changes. Returns ``(added, removed)``.
        """
        parsed = [parse_view_entry(e) for e in entries]
        names = [n for n, _ in parsed]
        repeated = repeated_names_reason(names)
        if repeated:
            raise InputError(repeated)
        if len(names) > self.max_views:
            raise InputError(f'too many views: {len(names)} listed, at most {self.max_views}')
        with self.lock:
            removed = [n for n in self.views if n not in names]
            for name in removed:
                del self.views[name]
                self._forget(name)
            added = []
            for name, pose in parsed:
                if name not in self.views:
                    self.add(name, pose)
                    added.append(name)
                elif pose is not None:
                    self.set_pose(name, pose)
            return added, removed

    def set_frame(self, images: Sequence[Optional[np.ndarray]], roll: float, pitch: float,
                  stamp_s: Optional[float] = None) -> None:
        """Copy one frame set (rig order; None blacks a camera out) and its attitude in."""
        if len(images) != len(self.rig):
            raise InputError(f'expected {len(self.rig)} images, got {len(images)}')
        with self.frame_lock.writing(), self.lock:
            for view in self.views.values():  # checked before anything changes
                view.set_attitude(roll, pitch)
            for i, image in enumerate(images):
                self.mosaic.set_image(i, image)
            self.attitude = (float(roll), float(pitch))
            self.stamp_s = stamp_s

    @contextmanager
    def drawing(self, name: str) -> Iterator[Tuple[LevelledView, np.ndarray]]:
        """
        Draw view ``name`` of the current frame set; yield ``(view, image)``.

        Inside, the frame set and the view hold still (the view's pose and attitude are
        those of the image); other views draw meanwhile. ``image`` is the view's own
        buffer: it stays as it is until this view is drawn again (copy it to keep it).
        :class:`NoSuchView` when there is no such view (or it is removed meanwhile).
        """
        with self.lock:
            if name not in self.views:
                raise NoSuchView(name)
        with self.frame_lock.reading():
            with self.lock:
                view = self.views.get(name)
                lock = self._view_locks.get(name)
            if view is None or lock is None:  # removed while a new frame set came in
                raise NoSuchView(name)
            with lock:
                with self.lock:
                    pose = self._poses_waiting.pop(name, None)
                if pose is not None:
                    view.set_pose(pose)
                yield view, self._draw(view)

    def render(self, name: str) -> np.ndarray:
        """Return a copy of view ``name`` of the current frame set."""
        with self.drawing(name) as (_, image):
            return image.copy()

    def render_all(self) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
        """Return ``{name: (image copy, K)}`` of every view for the current frame set."""
        out = {}
        for name in self.names():
            try:
                with self.drawing(name) as (view, image):
                    out[name] = (image.copy(), view.camera_matrix)
            except NoSuchView:
                continue   # removed meanwhile
        return out

    def _draw(self, view: LevelledView) -> np.ndarray:
        """
        Return ``view`` of the current frame set (its own buffer; in :meth:`drawing`).

        The views share each camera's image as the direct renderer reads it and its
        undistorted plane, each made once per frame set, and a view posed exactly as
        another one already drawn from this frame set copies that frame instead of
        drawing it again (:attr:`shared_frames` counts).
        """
        key = (self.mosaic.version, view.pose, view.attitude, view.width, view.height)
        with self.lock:
            if self._drawn_version != key[0]:
                self._drawn.clear()
                self._drawn_version = key[0]
            twin = self._drawn.get(key)
            names = [n for n, v in self.views.items() if v is twin] \
                if twin is not None and twin is not view else []
            twin_lock = self._view_locks.get(names[0]) if names else None
        # the twin's frame unless its own drawing is under way (never wait for it)
        if twin is not None and twin_lock is not None and twin_lock.acquire(blocking=False):
            try:
                if twin.last_frame_key == key:
                    with self.lock:
                        self.shared_frames += 1
                    return view.copy_frame(twin, key)
            finally:
                twin_lock.release()
        image = view.render(self.mosaic.image, self.mosaic.version)
        view.last_frame_key = key
        with self.lock:
            self._drawn[key] = view
        return image
