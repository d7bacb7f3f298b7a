"""
A levelled panorama video from a recorded camera rig (core of ``accelcal stitch BAG``).

Frame sets. The rig's image topics (one per camera, in rig order; sensor_msgs/Image or
CompressedImage) are streamed in time order; each camera's newest image is kept, and a
set is complete when every camera has an image within ``sync_s`` of the newest one. The
set's stamp is its newest image's; its cameras are then cleared, so each image serves
one frame at most. Images older than ``sync_s`` behind a newer one of another camera
simply wait to be replaced (a camera that stops sending stops the video, counted).

Attitude. Roll/pitch (rad, REP-103) at the set's stamp are interpolated linearly in the
attitude series (the attitude node's topic, or the tilt of the calibrated IMU); a set
farther than ``attitude_tolerance_s`` from the series' span is skipped (counted).

Output. ``*.mp4``/``*.avi``/``*.mkv``: one video (OpenCV VideoWriter, written to a
temporary name and renamed when complete); anything else: a folder of
``frame_NNNNNN.png`` (a failed run removes the frames it wrote and the folders it made).
"""
from dataclasses import dataclass, field
import os
from typing import Any, Callable, List, Optional, Sequence, Tuple, TYPE_CHECKING, Union

from accelcal_ros.errors import InputError
from accelcal_ros.fileio import missing_folders, remove_empty_folders
from accelcal_ros.recording import convert
from accelcal_ros.recording.bag import BagMessage, BagReader
from accelcal_ros.recording.streams import message_time_s, StampLog
import numpy as np
from numpy.typing import ArrayLike

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from accelcal_ros.panorama.stitch import Stitcher

VIDEO_SUFFIXES = {'.mp4': 'mp4v', '.avi': 'MJPG', '.mkv': 'mp4v'}
IMAGE_SUFFIXES = ('.png', '.jpg', '.jpeg', '.tif', '.tiff', '.bmp', '.webp', '.gif', '.ppm')
"""Suffixes of one image (or a format OpenCV does not write as video): not a frame folder."""


@dataclass
class StitchCounts:
    """What happened to the frame sets of a recording."""

    frames: int = 0
    no_attitude: int = 0
    images: int = 0
    warnings: List[str] = field(default_factory=list)
    """The image topics' stamp checks (backwards, repeated, far from the receive times)."""


class FrameSink:
    """Write frames to a video file (atomically) or to a folder of PNGs."""

    def __init__(self, path: Union[str, 'os.PathLike[str]'], fps: float) -> None:
        self.path = os.fspath(path)
        self.fps = float(fps)
        suffix = os.path.splitext(self.path)[1].lower()
        self.codec = VIDEO_SUFFIXES.get(suffix)
        self._writer: Any = None  # cv2.VideoWriter once the first frame gives the size
        self.count = 0
        self._frames: List[str] = []   # the frame files this run wrote
        self._made: List[str] = []     # the folders this run made (outermost first)
        if self.codec is None:
            if suffix in IMAGE_SUFFIXES:   # a folder named x.png is not what was asked for
                raise InputError(f'{self.path}: a recording gives many frames: write a video '
                                 f'({", ".join(VIDEO_SUFFIXES)}) or a folder of PNG frames '
                                 '(a name without an image suffix)')
            if os.path.exists(self.path) and os.listdir(self.path):
                raise InputError(f'{self.path} exists and is not empty; choose a new folder')
            self._made = missing_folders(self.path)
            os.makedirs(self.path, exist_ok=True)
        else:
            parent = os.path.dirname(os.path.abspath(self.path))
            self._tmp = os.path.join(parent, f'.{os.path.basename(self.path)}.partial-'
                                     f'{os.getpid()}{suffix}')

    def write(self, frame: np.ndarray) -> None:
        """Append one panorama (uint8, grey or BGR)."""
        import cv2

        if self.codec is None:
            from accelcal_ros.fileio import write_bytes_atomic

            ok, data = cv2.imencode('.png', frame)
            if not ok:
                raise InputError('cannot encode a panorama frame as PNG')
            name = os.path.join(self.path, f'frame_{self.count:06d}.png')
            write_bytes_atomic(name, data.tobytes())
            self._frames.append(name)
        else:
            if frame.ndim == 2:
                frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
            if self._writer is None:
                height, width = frame.shape[:2]
                self._writer = cv2.VideoWriter(self._tmp, cv2.VideoWriter.fourcc(*self.codec),
                                               self.fps, (width, height))
                if not self._writer.isOpened():
                    raise InputError(f'{self.path}: OpenCV cannot write {self.codec} video '
                                     'here; write a folder of PNG frames instead')
            self._writer.write(frame)
        self.count += 1

    def close(self, ok: bool = True) -> None:
        """
        Finish the video (renamed into place) or drop it when ``ok`` is False.

        A folder of frames dropped: the frames this run wrote are removed, then the
        folders it made if nothing else is in them; nothing else is touched.
        """
        if self.codec is None:
            if not ok:
                for name in self._frames:
                    try:
                        os.remove(name)
                    except FileNotFoundError:
                        pass
                remove_empty_folders(self._made)
                self._frames, self._made = [], []
            return
        if self._writer is not None:
            self._writer.release()
            if ok and self.count:
                os.replace(self._tmp, self.path)
            elif os.path.exists(self._tmp):
                os.remove(self._tmp)


def stitch_recording(bag: BagReader, stitcher: 'Stitcher', topics: Sequence[Optional[str]],
                     attitude: Sequence[ArrayLike], sink: FrameSink, sync_s: float = 0.05,
                     attitude_tolerance_s: float = 0.1,
                     before_render: Optional[Callable[[float], None]] = None) -> StitchCounts:
    """
    Render one panorama per complete frame set of ``topics`` into ``sink``.

    ``stitcher`` is a :class:`~accelcal_ros.panorama.stitch.Stitcher` for the rig (or
    anything with its ``channels``, ``set_image``, ``set_attitude`` and ``render``);
    ``attitude`` is ``(t_s, roll, pitch)`` sorted by time; ``before_render(stamp_s)``, if
    given, is called before each frame is rendered (a view moving along a path).
    """
    import cv2

    names: List[str] = []
    for i, topic in enumerate(topics):
        names.append(bag.select_topic(topic, (convert.IMAGE, convert.COMPRESSED_IMAGE),
                                      f'--images (camera {i})'))
    if len(set(names)) != len(names):
        raise InputError(f'--images names a topic twice: {names}')
    index = {name: i for i, name in enumerate(names)}
    t_att, roll, pitch = (np.asarray(a, dtype=float) for a in attitude)
    latest: List[Optional[Tuple[float, BagMessage]]] = [None] * len(names)
    counts = StitchCounts()
    logs = {name: StampLog() for name in names}
    for message in bag.messages(names, 'stitching'):   # the bar: images read of all
        i = index[message.topic]
        counts.images += 1
        logs[message.topic].add(message)
        latest[i] = (message_time_s(message, bag.stamp), message)
        ready = [item for item in latest if item is not None]
        if len(ready) < len(latest):
            continue
        stamps = [item[0] for item in ready]
        if max(stamps) - min(stamps) > sync_s:
            continue
        stamp = max(stamps)
        if stamp < t_att[0] - attitude_tolerance_s or stamp > t_att[-1] + attitude_tolerance_s:
            counts.no_attitude += 1
            latest = [None] * len(names)
            continue
        for k, (_, msg) in enumerate(ready):
            image = convert.image_array(msg.msg, msg.msgtype)
            if stitcher.channels == 1 and image.ndim == 3:
                image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            elif stitcher.channels == 3 and image.ndim == 2:
                image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
            try:
                stitcher.set_image(k, image)
            except InputError as exc:
                raise InputError(f'{names[k]}: {exc}') from None
        stitcher.set_attitude(float(np.interp(stamp, t_att, roll)),
                              float(np.interp(stamp, t_att, pitch)))
        if before_render is not None:
            before_render(stamp)
        sink.write(stitcher.render())
        counts.frames += 1
        latest = [None] * len(names)
    for name in names:   # images stamped alike or backwards were stitched without a word
        counts.warnings += logs[name].warnings(name, bag.stamp, repeats=True)
    return counts
