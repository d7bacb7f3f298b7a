"""
Offline commands of the panorama feature.

* ``accelcal stitch --rig rig.yaml --roll DEG --pitch DEG [--fov-h 180 --fov-v 120
  --width 3600 --height 2400 --projection spherical] -o pano.png img0.png img1.png ...``:
  stitch one set of images (in rig order) with the reference camera's roll and pitch
  (degrees, REP-103: roll right-side-down positive, pitch nose-down positive);
* ``accelcal study horizon``: paper A's Fig. 6 experiment (horizon deviation for pitch
  errors of -2 / +2 deg and for the package's own calibration error).
"""
import os
from typing import Any, Tuple, TYPE_CHECKING, Union

from accelcal_ros.cli_args import angle_deg, finite_float, float_in, int_in
from accelcal_ros.panorama.params import MAX_PANORAMA_SIDE_PX

if TYPE_CHECKING:  # pragma: no cover - annotations only
    import numpy as np

PathLike = Union[str, 'os.PathLike[str]']


def video_fps(bag: Any, topic: str, t: Any, requested: Any) -> float:
    """``--fps``, else the first camera topic's message rate over the attitude span (1-120)."""
    import numpy as np

    if requested is not None:
        return float(requested)
    first = bag.select_topic(topic, ('sensor_msgs/Image', 'sensor_msgs/CompressedImage'),
                             '--images')
    count = bag.topics()[first].count
    span = (t[-1] - t[0]) if len(t) > 1 else 0.0
    return float(np.clip(count / span, 1.0, 120.0)) if span > 0 else 10.0


def rig_images(paths: Any, rig: Any) -> list:
    """
    Read one image per rig camera, in rig order (stitch, view and serve of image files).

    A wrong count names the cameras; one file given for two cameras is refused (three
    copies of ``img0.png`` made a panorama with status 0).
    """
    from accelcal_ros.errors import InputError

    if len(paths) != len(rig):
        raise InputError(f'{len(paths)} image(s) given but the rig has {len(rig)} cameras '
                         f'({", ".join(rig.names)}); give one image per camera, in rig order')
    real = [os.path.realpath(p) for p in paths]
    for k, path in enumerate(real):
        if path in real[:k]:
            first = real.index(path)
            raise InputError(f'{paths[k]} is given for cameras {rig.names[first]} and '
                             f'{rig.names[k]}: give each camera its own image')
    return [read_image(p) for p in paths]


def bag_topics_and_model(args: Any, rig: Any) -> Tuple[list, Any]:
    """
    Return a BAG input's ``--images`` topics and its ``--calibration`` model (or None).

    One topic per rig camera, in rig order (``[None]`` picks the bag's only image topic
    for a one-camera rig); stitch, view and serve over a bag share it.
    """
    from accelcal_ros.errors import InputError

    if not args.image_topics and len(rig) > 1:
        raise InputError(f'give --images TOPIC ... for a BAG: one image topic per camera of '
                         f'the rig, in rig order ({len(rig)} cameras: {", ".join(rig.names)})')
    topics = args.image_topics or [None]
    if len(topics) != len(rig):
        raise InputError(f'{len(topics)} --images topic(s) for a rig of {len(rig)} cameras '
                         f'({", ".join(rig.names)}); give one topic per camera, in rig order')
    if not args.calibration:
        return topics, None
    from accelcal_ros.sensor.calibration_file import load_sensor_model

    return topics, load_sensor_model(args.calibration)


def add_rig_attitude_arguments(p: Any) -> None:
    """``--rig`` and the reference camera's ``--roll``/``--pitch`` (stitch and view)."""
    p.add_argument('--rig', required=True, help='rig YAML (cameras: name, width, height, '
                   'K, D, R; optional imu_to_camera)')
    p.add_argument('--roll', type=angle_deg(180.0),
                   help='reference camera roll, degrees (REP-103 body attitude)')
    p.add_argument('--pitch', type=angle_deg(90.0),
                   help='reference camera pitch, degrees (REP-103: nose down positive)')


def register(subparsers: Any, study_subparsers: Any) -> None:
    """Add this feature's subcommands to the ``accelcal`` parser."""
    p = subparsers.add_parser(
        'stitch', help='stitch one set of rig images into a levelled panorama')
    p.add_argument('images', nargs='+', help='camera images, in rig order; or one BAG '
                   '(rosbag2 directory, .mcap, .db3, ROS 1 .bag) with --images TOPIC...')
    _add_stitch_bag_arguments(p)
    add_rig_attitude_arguments(p)
    p.add_argument('--fov-h', type=float_in(0.0, 360.0, low_open=True), default=180.0,
                   help='horizontal extent, deg (180)')
    p.add_argument('--fov-v', type=float_in(0.0, 180.0, low_open=True), default=120.0,
                   help='vertical extent, deg (120)')
    p.add_argument('--width', type=int_in(2, MAX_PANORAMA_SIDE_PX), default=3600,
                   help='panorama width, px (3600)')
    p.add_argument('--height', type=int_in(2, MAX_PANORAMA_SIDE_PX), default=2400,
                   help='panorama height, px (2400)')
    p.add_argument('--projection', default='spherical', choices=('spherical', 'cylindrical'),
                   help='spherical (equal angle per pixel; default) or cylindrical')
    p.add_argument('--imu-to-camera', type=finite_float, nargs=9, metavar='R',
                   help='rotation body -> reference camera optical frame, 9 row-major '
                        "values (default: the rig file's imu_to_camera, else camera looks "
                        'along body +x)')
    p.add_argument('--blend-deg', type=float_in(0.0, 180.0), default=0.0,
                   help='feathered blending band at the seams, deg (default 0: off)')
    p.add_argument('-o', '--output', required=True, help='panorama image to write (PNG)')
    p.set_defaults(handler=_stitch)

    p = study_subparsers.add_parser(
        'horizon', help='paper A Fig. 6: horizon deviation for pitch errors and for the '
                        'own calibration error of the package')
    p.add_argument('--quick', action='store_true',
                   help='half resolution and 20 calibrations (a few seconds)')
    p.add_argument('--count', type=int_in(1, 10000), default=100,
                   help='calibrations fitted for the own-calibration row (100; at most 10000)')
    p.add_argument('--out', help='folder to write the three panoramas to (PNG)')
    p.set_defaults(handler=_study)

    from accelcal_ros.panorama import view_cli  # levelled views: accelcal view, study roi

    view_cli.register(subparsers, study_subparsers)


def read_image(path: PathLike) -> 'np.ndarray':
    """Read an 8-bit image (grey or BGR) with a clear error for unreadable files."""
    from accelcal_ros.errors import FileFormatError
    from accelcal_ros.fileio import read_image_file
    import cv2
    import numpy as np
    import os

    if not os.path.exists(path):
        raise FileFormatError(path, 'image not found')
    image = read_image_file(path, cv2.IMREAD_UNCHANGED)
    if image is None:
        raise FileFormatError(path, 'not an image OpenCV can read (PNG, JPEG, ...)')
    if image.dtype != np.uint8:
        raise FileFormatError(path, f'{image.dtype} pixels; the stitcher takes 8-bit images')
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    return image


def write_image(path: PathLike, image: 'np.ndarray') -> None:
    """Encode ``image`` by the file's extension (PNG if none) and write it atomically."""
    from accelcal_ros.errors import InputError
    from accelcal_ros.fileio import write_bytes_atomic
    import cv2
    import os

    ext = os.path.splitext(path)[1].lower() or '.png'
    try:
        ok, data = cv2.imencode(ext, image)
    except cv2.error:
        ok = False
    if not ok:
        raise InputError(f'{path}: cannot encode an image as {ext}; use .png or .jpg')
    write_bytes_atomic(path, data.tobytes())


def _stitch(args):
    import math

    from accelcal_ros.camera.rig import load_rig, resolve_imu_to_camera
    from accelcal_ros.errors import InputError
    from accelcal_ros.panorama.projection import PanoramaGeometry
    from accelcal_ros.panorama.stitch import Stitcher

    if is_bag_input(args):
        return _stitch_bag(args)
    if args.roll is None or args.pitch is None:
        raise InputError('stitch needs --roll and --pitch for image files (a BAG takes '
                         '--attitude or --imu)')
    rig = load_rig(args.rig)
    for name in ('roll', 'pitch', 'blend_deg'):
        if not math.isfinite(getattr(args, name)):
            raise InputError(f'--{name.replace("_", "-")} must be a finite number')
    geometry = PanoramaGeometry(args.width, args.height, args.fov_h, args.fov_v,
                                args.projection)
    imu_to_camera, _ = resolve_imu_to_camera(rig, args.imu_to_camera)
    images = rig_images(args.images, rig)
    channels = 1 if all(im.ndim == 2 for im in images) else 3
    stitcher = Stitcher(rig, geometry, imu_to_camera, blend_width_deg=args.blend_deg,
                        channels=channels)
    for i, (path, image) in enumerate(zip(args.images, images)):
        try:
            stitcher.set_image(i, image)
        except InputError as exc:
            raise InputError(f'{path}: {exc}') from None
    stitcher.set_attitude(math.radians(args.roll), math.radians(args.pitch))
    panorama = stitcher.render()
    write_image(args.output, panorama)
    seen = stitcher.coverage().mean()
    print(f'wrote {args.output}: {geometry.width}x{geometry.height} {geometry.projection} '
          f'panorama, {geometry.fov_h_deg:g} x {geometry.fov_v_deg:g} deg, '
          f'{100.0 * seen:.1f} % covered by {len(rig)} cameras; horizon at row '
          f'{geometry.horizon_row():g}')
    return 0


def _add_stitch_bag_arguments(p):
    """Options of ``stitch BAG``: image topics, attitude source, output video or folder."""
    from accelcal_ros.recording.cli_support import add_stamp_argument

    p.add_argument('--images', dest='image_topics', nargs='+', metavar='TOPIC',
                   help='bag: one sensor_msgs/Image or CompressedImage topic per camera, in rig '
                        'order (-o then names a video, .mp4/.avi/.mkv, or a folder of PNGs)')
    p.add_argument('--attitude', metavar='TOPIC',
                   help='bag: geometry_msgs/Vector3Stamped topic of the attitude node')
    p.add_argument('--imu', metavar='TOPIC',
                   help='bag: sensor_msgs/Imu topic; roll/pitch from its accelerometer, '
                        'calibrated with --calibration')
    p.add_argument('--calibration', metavar='YAML', help='bag: accelerometer calibration')
    p.add_argument('--sync-s', type=float_in(0.0, 10.0, low_open=True), default=0.05,
                   help='bag: the images of one frame lie within this of each other (s)')
    p.add_argument('--fps', type=float_in(0.0, 1000.0, low_open=True),
                   help='bag: video frame rate (default: from the frame stamps)')
    add_stamp_argument(p)


def _is_bag_input(args):
    from accelcal_ros.recording.bag import is_bag

    return len(args.images) == 1 and is_bag(args.images[0])


#: options that only a BAG input reads (``dest``, option), and those only image files read
_BAG_ONLY = (('image_topics', '--images'), ('attitude', '--attitude'), ('imu', '--imu'),
             ('calibration', '--calibration'), ('fps', '--fps'))
_IMAGES_ONLY = (('roll', '--roll'), ('pitch', '--pitch'))


def is_bag_input(args):
    """
    Return True when ``stitch``/``view``/``serve`` read a BAG, False for image files.

    Refuses (:class:`InputError`) an option the input would ignore: ``--roll``/``--pitch``
    with a BAG (its attitude comes from ``--attitude`` or ``--imu``), or ``--images``,
    ``--attitude``, ``--imu``, ``--calibration``, ``--fps`` with image files. Silently
    ignoring ``--roll 30`` on a bag gave frames identical to ``--roll 0``.
    """
    from accelcal_ros.errors import InputError

    bag = _is_bag_input(args)
    unread = [flag for dest, flag in (_IMAGES_ONLY if bag else _BAG_ONLY)
              if getattr(args, dest, None) is not None]
    if unread:
        raise InputError(f'{" and ".join(unread)} {"are" if len(unread) > 1 else "is"} not '
                         + ('read for a BAG, which takes its attitude from --attitude or '
                            '--imu' if bag else 'read for image files (they are for a BAG '
                            'input)') + ': leave it out')
    return bag


def _stitch_bag(args):
    """One levelled panorama per frame set of a recorded rig (video or PNG folder)."""
    from accelcal_ros.camera.rig import load_rig, resolve_imu_to_camera
    from accelcal_ros.errors import InputError
    from accelcal_ros.panorama.projection import PanoramaGeometry
    from accelcal_ros.panorama.stitch import Stitcher
    from accelcal_ros.recording.cli_support import open_bag, warn
    from accelcal_ros.panorama.bag import FrameSink, stitch_recording
    from accelcal_ros.recording.streams import attitude_series

    rig = load_rig(args.rig)
    topics, model = bag_topics_and_model(args, rig)
    geometry = PanoramaGeometry(args.width, args.height, args.fov_h, args.fov_v,
                                args.projection)
    imu_to_camera, _ = resolve_imu_to_camera(rig, args.imu_to_camera)
    stitcher = Stitcher(rig, geometry, imu_to_camera, blend_width_deg=args.blend_deg)
    with open_bag(args.images[0], args.stamp) as bag:
        t, roll, pitch, warnings = attitude_series(bag, args.attitude, args.imu, model)
        warn(warnings)
        fps = video_fps(bag, topics[0], t, args.fps)
        sink = FrameSink(args.output, fps)
        ok = False
        try:
            counts = stitch_recording(bag, stitcher, topics, (t, roll, pitch), sink,
                                      args.sync_s)
            warn(counts.warnings)
            ok = counts.frames > 0
        finally:
            sink.close(ok)
    if not counts.frames:
        raise InputError(f'no complete frame set with an attitude in {args.images[0]} '
                         f'({counts.images} images, {counts.no_attitude} sets without '
                         'attitude): check --images, --sync-s and the attitude topic')
    note = f', {counts.no_attitude} sets skipped (no attitude)' if counts.no_attitude else ''
    print(f'wrote {args.output}: {counts.frames} panoramas {geometry.width}x{geometry.height} '
          f'at {fps:.1f} fps from {counts.images} images{note}')
    return 0


def _study(args):
    from accelcal_ros.errors import InputError
    from accelcal_ros.panorama import horizon_study

    if args.count < 1:
        raise InputError('--count must be at least 1')
    models = args.fit_calibrations(count=args.count) if args.count else None
    horizon_study.run(count=args.count, quick=args.quick, out_dir=args.out, models=models)
    return 0
