"""
Levelled views (personal regions of interest) grown by the ``stitcher`` node (ROS wiring).

Why in the stitcher and not a node of their own: the views need exactly what the
stitcher already has -- every camera's frames, matched into sets with the attitude by
:class:`~.frame_sets.FrameSetPolicy` (sync, stalls, time jumps) -- so one process holds
one subscription per camera and decides the frame sets once; a second node would receive
every multi-megabyte frame a second time. The views render in a thread of their own
(:class:`RoiViews`), so the panorama's latency does not grow with them, and only views
somebody subscribes to are rendered; several views are drawn at once by
:data:`DRAW_THREADS` threads (:meth:`~.view_set.ViewSet.drawing`).

Per view ``<name>`` (parameter ``roi_views``: ``NAME`` or ``NAME:AZ,EL,FOV_H`` in
degrees; set it at run time to add, remove or point views):

* publishes ``roi/<name>/image`` (sensor_msgs/Image, the stitcher's ``output_encoding``,
  stamped with the frame set's stamp, frame_id ``<frame_id>_roi_<name>``) and
  ``roi/<name>/camera_info`` (sensor_msgs/CameraInfo: the virtual camera's ``K``,
  ``P = [K | 0]``, no distortion, same header), reliable depth 2;
* with ``roi_serve_port`` set, serves the same live frame sets in a browser (the page of
  ``accelcal serve``, :mod:`.serve`: one view per tab, not published as topics);
* subscribes ``roi/<name>/steer`` (geometry_msgs/Vector3Stamped: ``x`` = azimuth,
  ``y`` = elevation, ``z`` = horizontal field of view, radians, the conventions of
  :mod:`.view`), for a head tracker or joystick; a bad value (NaN, fov outside
  (0, 180) deg, elevation beyond +-90 deg) is logged with the reason and the view keeps
  its last pose. A steered pose is not written back into ``roi_views``.

A refused steer message (kind ``roi_steer``) and a frame set replaced by a newer one
before the views' thread rendered it (``roi_frame_sets``: the views fall behind) are
counted in the node's :class:`~accelcal_ros.rosutil.drops.DropCounter` and logged at most
every 10 s.
"""
from concurrent.futures import ThreadPoolExecutor
import threading

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.panorama.roi_params import ROI_PARAMS
from accelcal_ros.panorama.view_pose import ViewPose
from accelcal_ros.panorama.view_set import NoSuchView, ViewSet
from accelcal_ros.rosutil.images import image_cdr
from accelcal_ros.rosutil.params import ParameterSet
from geometry_msgs.msg import Vector3Stamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import CameraInfo, Image

VIEW_QOS = QoSProfile(depth=2, reliability=ReliabilityPolicy.RELIABLE)
DRAW_THREADS = 2
"""Views of one frame set drawn at once (the remap, the JPEG and the copies release the
GIL; a 2-core machine's cores)."""


class RoiViews:
    """The views of one node: parameters, publishers, steering and the render thread."""

    def __init__(self, node, drops):
        self.node = node
        self.drops = drops
        self.views = None
        self._io = {}  # name -> (image publisher, info publisher, steer subscription)
        self._pending = None
        self._cond = threading.Condition()
        self._stop = False
        self._warned = set()
        self._pool = None
        self._thread = None
        self.server = None
        self.published = 0
        self.params = ParameterSet(node, ROI_PARAMS, on_change=self._on_change)

    def start(self, rig, imu_to_camera, encoding='bgr8', frame_id=lambda: 'panorama'):
        """
        Create the views of ``roi_views`` for ``rig`` and start the render thread.

        ``frame_id()``: the panorama's frame id when a frame is published (settable at
        run time); a view's is ``<frame_id>_roi_<name>``.
        """
        self.encoding = encoding
        self.frame_id = frame_id
        v = self.params.values
        self.views = ViewSet(rig, imu_to_camera, 1 if encoding == 'mono8' else 3,
                             v['roi_max_views'], v['roi_width'], v['roi_height'])
        self._apply(v['roi_views'])
        self.server = self._browser_server(rig, imu_to_camera, v)
        self._thread = threading.Thread(target=self._loop, name='roi_views', daemon=True)
        self._thread.start()

    def _browser_server(self, rig, imu_to_camera, v):
        """Start the live browser server when ``roi_serve_port`` is set (else None)."""
        if not v['roi_serve_port']:
            return None
        from accelcal_ros.panorama.serve import is_loopback, ViewServer

        host, token = v['roi_serve_host'], v['roi_serve_token'] or None
        if not is_loopback(host) and token is None:
            raise InputError(f'roi_serve_host {host!r} is not a loopback address: set '
                             'roi_serve_token, which every browser request must then carry')
        tabs = ViewSet(rig, imu_to_camera, 3, v['roi_max_views'], v['roi_width'],
                       v['roi_height'])
        server = ViewServer(tabs, [], token=token, live=True)
        server.start(host, v['roi_serve_port'])
        self.node.get_logger().info(f'live views in a browser on {server.url}'
                                    + ('?token=...' if token else ''))
        return server

    # -- views ----------------------------------------------------------------------------
    def _on_change(self, name, value):
        if name == 'roi_views' and self.views is not None:
            self._apply(value)

    def _apply(self, entries):
        added, removed = self.views.apply_entries(entries)
        for name in removed:
            image_pub, info_pub, steer = self._io.pop(name)
            self.node.destroy_publisher(image_pub)
            self.node.destroy_publisher(info_pub)
            self.node.destroy_subscription(steer)
        for name in added:
            self._io[name] = (
                self.node.create_publisher(Image, f'roi/{name}/image', VIEW_QOS),
                self.node.create_publisher(CameraInfo, f'roi/{name}/camera_info', VIEW_QOS),
                self.node.create_subscription(
                    Vector3Stamped, f'roi/{name}/steer',
                    lambda msg, name=name: self._on_steer(name, msg), 10))
        if added or removed:
            self.node.get_logger().info(
                f'views: {", ".join(self.views.names()) or "none"}'
                + (f' (added {", ".join(added)})' if added else '')
                + (f' (removed {", ".join(removed)})' if removed else ''))

    def _on_steer(self, name, msg):
        v = msg.vector
        try:
            self.views.set_pose(name, ViewPose(v.x, v.y, v.z))
        except InputError as exc:
            self.drops.drop('roi_steer', f'roi/{name}/steer rejected: {exc}; the view keeps '
                            'its last pose')

    # -- frames ---------------------------------------------------------------------------
    def submit(self, frame_set):
        """Hand the newest frame set to the render thread (an older pending one is dropped)."""
        if not self._io and self.server is None:
            return
        with self._cond:
            replaced = self._pending is not None
            self._pending = frame_set
            self._cond.notify()
        if replaced:
            self.drops.drop('roi_frame_sets', 'levelled views: a frame set replaced by a '
                            'newer one before it was rendered (the views fall behind)')

    def close(self):
        """Stop the render thread."""
        with self._cond:
            self._stop = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join(timeout=5.0)
        if self._pool is not None:
            self._pool.shutdown(wait=False, cancel_futures=True)
        if self.server is not None:
            self.server.stop()

    def _loop(self):
        while True:
            with self._cond:
                while self._pending is None and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                frame_set, self._pending = self._pending, None
            try:
                self._render(frame_set)
            except Exception as exc:  # noqa: B902 - the thread lives on; say what happened
                key = type(exc).__name__ if not isinstance(exc, AccelcalError) else str(exc)
                if key not in self._warned:
                    self._warned.add(key)
                    self.node.get_logger().warning(f'views: {type(exc).__name__}: {exc}')

    def _render(self, frame_set):
        if self.server is not None:
            self.server.push_frame(frame_set.images, frame_set.roll_rad, frame_set.pitch_rad,
                                   frame_set.stamp_s)
        wanted = [name for name, (pub, info, _) in list(self._io.items())
                  if pub.get_subscription_count() or info.get_subscription_count()]
        if not wanted:
            return
        self.views.set_frame(frame_set.images, frame_set.roll_rad, frame_set.pitch_rad,
                             frame_set.stamp_s)
        total_ns = int(round(frame_set.stamp_s * 1e9))
        sec, nanosec = divmod(total_ns, 1_000_000_000)
        if len(wanted) == 1:
            self.published += self._publish(wanted[0], sec, nanosec)
            return
        if self._pool is None:
            self._pool = ThreadPoolExecutor(DRAW_THREADS, thread_name_prefix='roi_draw')
        self.published += sum(self._pool.map(
            lambda name: self._publish(name, sec, nanosec), wanted))

    def _publish(self, name, sec, nanosec):
        """Draw view ``name`` of the frame set and publish it; return 1 (0: removed)."""
        io = self._io.get(name)
        if io is None:
            return 0
        try:
            with self.views.drawing(name) as (view, image):
                k = view.camera_matrix
                frame_id = f'{self.frame_id()}_roi_{name}'
                data = image_cdr(image, self.encoding, sec, nanosec, frame_id)
        except NoSuchView:  # removed meanwhile
            return 0
        io[0].publish(data)
        io[1].publish(self._camera_info(k, image.shape, sec, nanosec, frame_id))
        return 1

    @staticmethod
    def _camera_info(k, shape, sec, nanosec, frame_id):
        info = CameraInfo()
        info.header.stamp.sec, info.header.stamp.nanosec = sec, nanosec
        info.header.frame_id = frame_id
        info.height, info.width = int(shape[0]), int(shape[1])
        info.distortion_model = 'plumb_bob'
        info.d = [0.0] * 5
        info.k = [float(x) for x in k.reshape(-1)]
        info.r = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
        info.p = [k[0, 0], 0.0, k[0, 2], 0.0, 0.0, k[1, 1], k[1, 2], 0.0, 0.0, 0.0, 1.0, 0.0]
        info.p = [float(x) for x in info.p]
        return info
