"""
Offline commands of the levelled views (personal regions of interest).

* ``accelcal view --rig RIG --roll R --pitch P --azimuth A --elevation E --fov-h F
  --width W --height H -o view.png IMAGES...``: one levelled pinhole view (degrees,
  REP-103 attitude; azimuth 0 = the panorama's centre column, positive right; elevation
  positive up) of one set of rig images, in rig order;
* ``accelcal view --rig RIG --images TOPIC... --attitude TOPIC|--imu TOPIC -o view.mp4
  BAG``: a video of the view over a recording, optionally moving along ``--path
  path.csv`` (columns ``t,azimuth,elevation,fov_h``: seconds from the first frame set,
  degrees; linear interpolation, held before the first and after the last row);
* ``accelcal study roi``: :mod:`.roi_study`.
"""
import math
from typing import Any, cast, Dict, Optional, Tuple

from accelcal_ros.cli_args import angle_deg, finite_float, float_in, int_in
from accelcal_ros.errors import InputError
from accelcal_ros.panorama.view_pose import (MAX_FOV_H_DEG, MAX_VIEW_SIDE_PX, MIN_FOV_H_DEG,
                                             MIN_VIEW_SIDE_PX, ViewPose)
import numpy as np


class ViewPath:
    """
    A recorded operator: the view's pose along time, from ``t,azimuth,elevation,fov_h``.

    ``t`` in seconds (strictly increasing), angles in degrees; :meth:`at` interpolates
    linearly (azimuth unwrapped, so 179 -> -179 turns by 2 deg) and holds the end values
    outside the span. Every row is checked as a :class:`~.view.ViewPose`.
    """

    def __init__(self, t_s: Any, azimuth_deg: Any, elevation_deg: Any, fov_h_deg: Any,
                 source: str = 'path') -> None:
        self.t = np.asarray(t_s, dtype=float)
        if self.t.size == 0:
            raise InputError(f'{source}: no rows (header t,azimuth,elevation,fov_h and one '
                             'row per time)')
        for k, row in enumerate(zip(azimuth_deg, elevation_deg, fov_h_deg)):
            try:
                ViewPose.from_degrees(*row)
            except InputError as exc:
                raise InputError(f'{source}: row {k + 1}: {exc}') from None
        self.azimuth = np.degrees(np.unwrap(np.radians(np.asarray(azimuth_deg, float))))
        self.elevation = np.asarray(elevation_deg, dtype=float)
        self.fov_h = np.asarray(fov_h_deg, dtype=float)

    @classmethod
    def load(cls, path: str) -> 'ViewPath':
        """Read a path CSV (errors name the file and line)."""
        from accelcal_ros.schema import VIEW_PATH_CSV
        from accelcal_ros.textformats import read_numeric_csv

        table: Dict[str, np.ndarray] = read_numeric_csv(
            path, VIEW_PATH_CSV.required, finite=True, increasing='t')
        return cls(table['t'], table['azimuth'], table['elevation'], table['fov_h'], path)

    def at(self, t_s: float) -> ViewPose:
        """Return the pose at ``t_s`` (seconds on the path's clock)."""
        return ViewPose.from_degrees(float(np.interp(t_s, self.t, self.azimuth)),
                                     float(np.interp(t_s, self.t, self.elevation)),
                                     float(np.interp(t_s, self.t, self.fov_h)))


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add ``view`` (and ``study roi``) to the ``accelcal`` parser."""
    from accelcal_ros.panorama.cli import _add_stitch_bag_arguments, add_rig_attitude_arguments

    p = subparsers.add_parser(
        'view', help='a levelled pinhole view (region of interest) of rig images or a bag')
    p.add_argument('images', nargs='+', help='camera images, in rig order; or one BAG '
                   'with --images TOPIC... (then -o names a video or a folder of PNGs)')
    _add_stitch_bag_arguments(p)
    add_rig_attitude_arguments(p)
    p.add_argument('--azimuth', type=angle_deg(360.0), default=0.0,
                   help='view direction, deg: 0 = the panorama centre, positive right (0)')
    p.add_argument('--elevation', type=angle_deg(90.0), default=0.0,
                   help='view direction, deg: positive up (0)')
    p.add_argument('--fov-h', type=float_in(MIN_FOV_H_DEG, MAX_FOV_H_DEG), default=60.0,
                   help=f'horizontal field of view, deg, in [{MIN_FOV_H_DEG:g}, '
                        f'{MAX_FOV_H_DEG:g}] (60)')
    p.add_argument('--width', type=int_in(MIN_VIEW_SIDE_PX, MAX_VIEW_SIDE_PX), default=1280,
                   help='view width, px (1280)')
    p.add_argument('--height', type=int_in(MIN_VIEW_SIDE_PX, MAX_VIEW_SIDE_PX), default=720,
                   help='view height, px (720)')
    p.add_argument('--path', dest='view_path', metavar='CSV',
                   help='bag: the view moves along this path (t,azimuth,elevation,fov_h; '
                        's from the first frame set, deg)')
    p.add_argument('--imu-to-camera', type=finite_float, nargs=9, metavar='R',
                   help='rotation body -> reference camera optical frame, 9 row-major '
                        "values (default: the rig file's imu_to_camera)")
    p.add_argument('-o', '--output', required=True, help='view image to write (PNG/JPEG); '
                   'for a bag a video (.mp4/.avi/.mkv) or a folder of PNGs')
    p.set_defaults(handler=_view)

    p = subparsers.add_parser(
        'serve', help='levelled views of rig images or a bag in a browser, one per tab')
    p.add_argument('images', nargs='+', help='camera images, in rig order (with --roll '
                   '--pitch); or one BAG with --images TOPIC... (played in a loop)')
    _add_stitch_bag_arguments(p)
    p.add_argument('--rig', required=True, help='rig YAML')
    p.add_argument('--roll', type=angle_deg(180.0), help='reference camera roll, degrees')
    p.add_argument('--pitch', type=angle_deg(90.0), help='reference camera pitch, degrees')
    p.add_argument('--imu-to-camera', type=finite_float, nargs=9, metavar='R',
                   help="rotation body -> reference camera optical frame (default: the rig's)")
    p.add_argument('--host', default='127.0.0.1', help='address to listen on (127.0.0.1: '
                   'this machine only; any other address requires the token)')
    p.add_argument('--port', type=int_in(0, 65535), default=8080, help='TCP port (8080)')
    p.add_argument('--token', help='token every request must carry (?token=...); '
                   'generated and printed when serving beyond this machine without one')
    p.add_argument('--max-views', type=int_in(1, 64), default=8,
                   help='most tabs served at once; more are refused (8)')
    p.add_argument('--width', type=int_in(MIN_VIEW_SIDE_PX, MAX_VIEW_SIDE_PX), default=960,
                   help='view width, px (960)')
    p.add_argument('--height', type=int_in(MIN_VIEW_SIDE_PX, MAX_VIEW_SIDE_PX), default=540,
                   help='view height, px (540)')
    p.add_argument('--max-frames', type=int_in(1, 10000), default=300,
                   help='bag: frame sets kept in memory and played in a loop (300)')
    p.add_argument('--quality', type=int_in(1, 100), default=80, help='JPEG quality (80)')
    p.set_defaults(handler=_serve)

    p = study_subparsers.add_parser(
        'roi', help='false roll of the horizon inside a view panning across the sector, '
                    'for pitch errors and the package calibration (paper A, Fig. 6)')
    p.add_argument('--quick', action='store_true', help='fewer azimuths and calibrations')
    p.add_argument('--count', type=int_in(1, 10000), default=100,
                   help='calibrations fitted for the own-calibration row (100; at most 10000)')
    p.add_argument('--json', help='write the table as JSON here')
    p.set_defaults(handler=_study)


def _make_view(args: Any, rig: Any, layout: Any) -> Any:
    from accelcal_ros.camera.rig import resolve_imu_to_camera
    from accelcal_ros.panorama.view import LevelledView

    imu_to_camera, _ = resolve_imu_to_camera(rig, args.imu_to_camera)
    pose = ViewPose.from_degrees(args.azimuth, args.elevation, args.fov_h)
    return LevelledView(rig, layout, args.width, args.height, pose, imu_to_camera)


def _view(args: Any) -> int:
    from accelcal_ros.camera.rig import load_rig
    from accelcal_ros.panorama.cli import is_bag_input, rig_images, write_image
    from accelcal_ros.panorama.view import ViewMosaic

    if is_bag_input(args):
        return _view_bag(args)
    if args.view_path:
        raise InputError('--path moves the view over a BAG; for image files give '
                         '--azimuth/--elevation/--fov-h')
    if args.roll is None or args.pitch is None:
        raise InputError('view needs --roll and --pitch for image files (a BAG takes '
                         '--attitude or --imu)')
    rig = load_rig(args.rig)
    images = rig_images(args.images, rig)
    mosaic = ViewMosaic(rig, 1 if all(im.ndim == 2 for im in images) else 3)
    for i, (path, image) in enumerate(zip(args.images, images)):
        try:
            mosaic.set_image(i, image)
        except InputError as exc:
            raise InputError(f'{path}: {exc}') from None
    view = _make_view(args, rig, mosaic.layout)
    view.set_attitude(math.radians(args.roll), math.radians(args.pitch))
    write_image(args.output, view.render(mosaic.image))
    az, el, fov = view.pose.degrees()
    k = view.camera_matrix
    row = view.horizon_row()
    horizon = 'horizon not in view' if row is None else f'horizon at row {row:.2f}'
    print(f'wrote {args.output}: {view.width}x{view.height} view at azimuth {az:g}, '
          f'elevation {el:g} deg, fov_h {fov:g} deg (fx = fy = {k[0, 0]:.2f} px); '
          f'{100.0 * view.covered_fraction():.1f} % covered; {horizon}')
    return 0


class _ViewFrames:
    """What :func:`~.bag.stitch_recording` needs of a stitcher, for one moving view."""

    def __init__(self, rig: Any, view_args: Any, path: Optional[ViewPath]) -> None:
        from accelcal_ros.panorama.view import ViewMosaic

        self.mosaic = ViewMosaic(rig)
        self.channels = self.mosaic.channels
        self.view = _make_view(view_args, rig, self.mosaic.layout)
        self.path = path
        self.first_stamp: Optional[float] = None
        self.covered: list = []

    def set_image(self, index: int, image: np.ndarray) -> None:
        self.mosaic.set_image(index, image)

    def set_attitude(self, roll: float, pitch: float) -> None:
        self.view.set_attitude(roll, pitch)

    def at_stamp(self, stamp_s: float) -> None:
        if self.first_stamp is None:
            self.first_stamp = stamp_s
        if self.path is not None:
            self.view.set_pose(self.path.at(stamp_s - self.first_stamp))

    def render(self) -> np.ndarray:
        frame = self.view.render(self.mosaic.image)
        self.covered.append(self.view.covered_fraction())
        return frame


def _view_bag(args: Any) -> int:
    """One levelled view per frame set of a recorded rig (video or PNG folder)."""
    from accelcal_ros.camera.rig import load_rig
    from accelcal_ros.panorama.bag import FrameSink, stitch_recording
    from accelcal_ros.panorama.cli import bag_topics_and_model, video_fps
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.recording.streams import attitude_series

    rig = load_rig(args.rig)
    topics, model = bag_topics_and_model(args, rig)
    path = ViewPath.load(args.view_path) if args.view_path else None
    frames = _ViewFrames(rig, args, path)
    with open_bag(args.images[0], args.stamp) as bag:
        t, roll, pitch, warnings = attitude_series(bag, args.attitude, args.imu, model)
        warn(warnings)
        fps = video_fps(bag, topics[0], t, args.fps)
        sink = FrameSink(args.output, fps)
        ok = False
        try:
            counts = stitch_recording(bag, cast(Any, frames), topics, (t, roll, pitch), sink,
                                      args.sync_s, before_render=frames.at_stamp)
            warn(counts.warnings)
            ok = counts.frames > 0
        finally:
            sink.close(ok)
    if not counts.frames:
        raise InputError(f'no complete frame set with an attitude in {args.images[0]} '
                         f'({counts.images} images, {counts.no_attitude} sets without '
                         'attitude): check --images, --sync-s and the attitude topic')
    moving = ' along ' + args.view_path if path is not None else ''
    print(f'wrote {args.output}: {counts.frames} views {args.width}x{args.height}{moving} at '
          f'{fps:.1f} fps, {100.0 * float(np.mean(frames.covered)):.1f} % covered on '
          f'average, {frames.view.rebuild_count} lookup rebuilds')
    return 0


class _Collect:
    """Frame sets of a bag kept in memory (what :func:`stitch_recording` hands over)."""

    def __init__(self, rig: Any, limit: int) -> None:
        self.channels = 3
        self.rig = rig
        self.limit = limit
        self.images: list = [None] * len(rig)
        self.sets: list = []
        self.attitude = (0.0, 0.0)
        self.stamp = 0.0

    def set_image(self, index: int, image: np.ndarray) -> None:
        self.images[index] = np.array(image)

    def set_attitude(self, roll: float, pitch: float) -> None:
        self.attitude = (roll, pitch)

    def at_stamp(self, stamp_s: float) -> None:
        self.stamp = stamp_s

    def render(self) -> np.ndarray:
        if len(self.sets) < self.limit:
            self.sets.append((list(self.images), *self.attitude, self.stamp))
        return np.zeros((2, 2), np.uint8)


class _NoSink:
    def write(self, frame: np.ndarray) -> None:
        pass


def _serve_frames(args: Any, rig: Any) -> Tuple[list, float]:
    """Return ``(frame sets, fps)`` of the command's images or bag."""
    from accelcal_ros.panorama.cli import bag_topics_and_model, is_bag_input, rig_images

    if not is_bag_input(args):
        if args.roll is None or args.pitch is None:
            raise InputError('serve needs --roll and --pitch for image files (a BAG takes '
                             '--attitude or --imu)')
        images = rig_images(args.images, rig)
        return [(images, math.radians(args.roll), math.radians(args.pitch), 0.0)], 10.0
    from accelcal_ros.panorama.bag import stitch_recording
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.recording.streams import attitude_series

    topics, model = bag_topics_and_model(args, rig)
    collect = _Collect(rig, args.max_frames)
    with open_bag(args.images[0], args.stamp) as bag:
        t, roll, pitch, warnings = attitude_series(bag, args.attitude, args.imu, model)
        warn(warnings)
        counts = stitch_recording(bag, cast(Any, collect), topics, (t, roll, pitch),
                                  cast(Any, _NoSink()), args.sync_s,
                                  before_render=collect.at_stamp)
        warn(counts.warnings)
    if not collect.sets:
        raise InputError(f'no complete frame set with an attitude in {args.images[0]}')
    stamps = [s[3] for s in collect.sets]
    span = stamps[-1] - stamps[0]
    fps = args.fps or (float(np.clip((len(stamps) - 1) / span, 1.0, 60.0)) if span > 0
                       else 10.0)
    return collect.sets, fps


def _serve(args: Any) -> int:
    from accelcal_ros.camera.rig import load_rig, resolve_imu_to_camera
    from accelcal_ros.panorama.serve import (is_loopback, make_token, serve_forever,
                                             ViewServer)
    from accelcal_ros.panorama.view_set import ViewSet

    rig = load_rig(args.rig)
    token = args.token
    if token is not None and not token.strip():
        raise InputError('--token must not be empty')
    if not is_loopback(args.host) and token is None:
        token = make_token()
    frames, fps = _serve_frames(args, rig)
    imu_to_camera, _ = resolve_imu_to_camera(rig, args.imu_to_camera)
    views = ViewSet(rig, imu_to_camera, 3, args.max_views, args.width, args.height)
    server = ViewServer(views, frames, fps, token, args.quality)

    def announce(url: str) -> None:
        """Say where the page is, once listening (the bound port; the token quoted)."""
        print(f'serving {len(frames)} frame set(s) at {fps:.1f} fps on {url} (up to '
              f'{args.max_views} tabs of {args.width}x{args.height}; Ctrl-C stops)',
              flush=True)

    serve_forever(server, args.host, args.port, announce)
    return 0


def _study(args: Any) -> int:
    from accelcal_ros.panorama import roi_study

    models = args.fit_calibrations(count=args.count)
    roi_study.run(count=args.count, quick=args.quick, json_path=args.json, models=models)
    return 0
