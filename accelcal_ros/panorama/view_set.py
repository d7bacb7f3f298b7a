"""
Several named levelled views of one rig, sharing one mosaic (pure; the node and the server use it).

Each frame set is copied once into a :class:`~.view.ViewMosaic`; every view renders from
it with its own lookup (:class:`~.view.LevelledView`). Names are ROS name tokens (they
become topics ``roi/<name>/image``): a letter, then letters, digits and single
underscores, at most :data:`MAX_NAME_LENGTH` characters. At most ``max_views`` views
exist at once; one more is refused with the cap in the message and the others keep
working. Every method is thread-safe (one lock): a steering callback may move a view
while another thread renders.

Parameter form of a view (``roi_views`` of the node): ``NAME`` or
``NAME:AZIMUTH,ELEVATION,FOV_H`` in degrees, e.g. ``front:0,0,60``.
"""
import re
import threading
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple

from accelcal_ros.errors import InputError
from accelcal_ros.panorama.view import (check_view_size, LevelledView, ViewMosaic,
                                        ViewPose)
from accelcal_ros.panorama.view_grid import CameraSources
from accelcal_ros.panorama.view_warp import CameraPlanes
import numpy as np
from numpy.typing import ArrayLike

MAX_NAME_LENGTH = 48
"""Longest view name (it becomes part of two topic names)."""
DEFAULT_MAX_VIEWS = 8
"""Default cap on the number of views at once."""
_NAME = re.compile(r'[A-Za-z][A-Za-z0-9]*(_[A-Za-z0-9]+)*\Z')


def check_view_name(name: Any) -> str:
    """Return ``name`` if it is a valid ROS name token, else raise :class:`InputError`."""
    if not isinstance(name, str) or not name:
        raise InputError(f'view name must be a non-empty string, got {name!r}')
    if len(name) > MAX_NAME_LENGTH or not _NAME.match(name):
        raise InputError(f'view name {name!r} is not a valid topic name token (a letter, '
                         'then letters, digits and single underscores, at most '
                         f'{MAX_NAME_LENGTH} characters)')
    return name


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
            return view

    def remove(self, name: str) -> None:
        """Remove a view (InputError if there is none of that name)."""
        with self.lock:
            if self.views.pop(name, None) is None:
                raise InputError(f'no view named {name!r}')

    def set_pose(self, name: str, pose: ViewPose) -> None:
        """Point view ``name`` (the view keeps its last pose when this raises)."""
        with self.lock:
            view = self.views.get(name)
            if view is None:
                raise InputError(f'no view named {name!r}')
            view.set_pose(pose)

    def apply_entries(self, entries: Iterable[str]) -> Tuple[List[str], List[str]]:
        """
        Make the views those of ``entries`` (``NAME`` or ``NAME:AZ,EL,FOV``): all or nothing.

        New names are added, missing ones removed, listed poses applied; every entry is
        checked before anything changes. Returns ``(added, removed)``.
        """
        parsed = [parse_view_entry(e) for e in entries]
        names = [n for n, _ in parsed]
        if len(set(names)) != len(names):
            raise InputError(f'a view name is listed twice: {names}')
        if len(names) > self.max_views:
            raise InputError(f'too many views: {len(names)} listed, at most {self.max_views}')
        with self.lock:
            removed = [n for n in self.views if n not in names]
            for name in removed:
                del self.views[name]
            added = []
            for name, pose in parsed:
                if name not in self.views:
                    self.add(name, pose)
                    added.append(name)
                elif pose is not None:
                    self.views[name].set_pose(pose)
            return added, removed

    def set_frame(self, images: Sequence[Optional[np.ndarray]], roll: float, pitch: float,
                  stamp_s: Optional[float] = None) -> None:
        """Copy one frame set (rig order; None blacks a camera out) and its attitude in."""
        if len(images) != len(self.rig):
            raise InputError(f'expected {len(self.rig)} images, got {len(images)}')
        with self.lock:
            for view in self.views.values():  # checked before anything changes
                view.set_attitude(roll, pitch)
            for i, image in enumerate(images):
                self.mosaic.set_image(i, image)
            self.attitude = (float(roll), float(pitch))
            self.stamp_s = stamp_s

    def render(self, name: str) -> np.ndarray:
        """Return a copy of view ``name`` of the current frame set."""
        with self.lock:
            view = self.views.get(name)
            if view is None:
                raise InputError(f'no view named {name!r}')
            return self.render_view(view).copy()

    def render_all(self) -> Dict[str, Tuple[np.ndarray, np.ndarray]]:
        """Return ``{name: (image copy, K)}`` of every view for the current frame set."""
        with self.lock:
            return {name: (self.render_view(view).copy(), view.camera_matrix)
                    for name, view in self.views.items()}

    def render_view(self, view: LevelledView) -> np.ndarray:
        """
        Return ``view`` of the current frame set (its own buffer; hold :attr:`lock`).

        The views share each camera's image as the direct renderer reads it and its
        undistorted plane, each made once per frame set, and a view posed exactly as
        another one already drawn from this frame set copies that frame instead of
        drawing it again (:attr:`shared_frames` counts).
        """
        key = (self.mosaic.version, view.pose, view.attitude, view.width, view.height)
        if self._drawn_version != key[0]:
            self._drawn.clear()
            self._drawn_version = key[0]
        twin = self._drawn.get(key)
        if twin is not None and twin is not view and twin.last_frame_key == key and \
                any(v is twin for v in self.views.values()):
            self.shared_frames += 1
            return view.copy_frame(twin, key)
        image = view.render(self.mosaic.image, self.mosaic.version)
        view.last_frame_key = key
        self._drawn[key] = view
        return image
