"""
Node ``cloud_assembler``: georeferenced point cloud from scans and navigation odometry.

Subscribes ``points`` (sensor_msgs/PointCloud2 with a per-point time field ``time`` (s,
relative to the header stamp), ``t`` (ns, relative) or ``timestamp`` (s, absolute);
best effort, or reliable with ``points_reliable``) and ``odom`` (nav_msgs/Odometry: pose
of the IMU body, ``child_frame_id``, in the navigation frame ``header.frame_id``;
reliable QoS depth 2000: 10 s of 200 Hz). Publishes each
georeferenced scan on ``points_georef`` (PointCloud2 in the navigation frame, fields
x y z [intensity ring] timestamp) and ``/diagnostics`` (counts, boresight, last save;
WARN without a boresight, ERROR after a failed write; ``scans_waiting``: scans waiting
for odometry to cover them). ``cloud_assembler/save``
(std_srvs/Trigger) writes the accumulated cloud to ``output_file`` (.ply or .pcd,
atomic), as does shutdown (after georeferencing what still waits, with the poses
there are); a failed write is logged at ERROR. Without a boresight (no
file, rpy all zero) it warns loudly at start and in every diagnostics message.
Frames and equation: :mod:`accelcal_ros.lidar.georef`. With ``map_crs`` the odometry is
in that projected CRS (UTM): points go out in the ``map`` frame anchored at
``map_origin`` (logged) and ``save`` writes .laz/.las with the CRS
(:mod:`accelcal_ros.lidar.map_output`).

Dropped input, counted in one :class:`~accelcal_ros.rosutil.drops.DropCounter`
(``cloud_assembler: dropped messages``) and logged at most every 10 s per kind:
``scans`` (no x/y/z or time field, a bad layout, or no odometry yet) and ``odometry``
(NaN, a quaternion of norm != 1, a stamp not after the previous one). Points of a scan
outside the odometry's time span, or between two poses further apart than
``max_pose_gap_s``, are dropped, never extrapolated or interpolated across (said once,
counted in the scan totals).

Threads: the subscriptions' callbacks only hand their message to an inbox (a deque, in
arrival order) and never wait for the georeferencing; the 50 Hz timer drains it into the
core and georeferences what is ready, on the node's running clock
(:class:`~accelcal_ros.lidar.assembler.RunningClock`: a scan's wait for odometry does
not run out while the process, odometry callbacks included, was starved of CPU).
Callbacks that waited on the core's lock while the timer worked made the
MultiThreadedExecutor this node once used take 0.3-4 s per scan instead of 6 ms (odometry
then overflowed its queue: 0.5-0.9 s pose gaps in the demo's drive); it runs on the
EventsExecutor, as the other nodes.
"""
from collections import deque
import threading
import time

from accelcal_ros.errors import AccelcalError, InputError
from accelcal_ros.lidar.map_output import map_output_problem
from accelcal_ros.lidar.params import CLOUD_ASSEMBLER_PARAMS as SPECS
from accelcal_ros.rosutil.diagnostics import (diagnostic_status, diagnostics_publisher,
                                              publish_diagnostics)
from accelcal_ros.rosutil.drops import DropCounter
from accelcal_ros.rosutil.params import ParameterSet
from accelcal_ros.rosutil.pointcloud2 import array_to_pointcloud2, pointcloud2_to_array
from accelcal_ros.rosutil.runner import run
from accelcal_ros.rosutil.stamps import seconds_to_stamp, stamp_to_seconds
from builtin_interfaces.msg import Time
from nav_msgs.msg import Odometry
import numpy as np
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import PointCloud2, PointField
from std_msgs.msg import Header
from std_srvs.srv import Trigger

ODOMETRY_QUEUE_DEPTH = 2000
"""Odometry messages the subscription queues (10 s at 200 Hz, about 1.5 MB): poses are
small, and one lost on a moving platform is a gap whose points are dropped."""
NO_BORESIGHT = ('NO BORESIGHT GIVEN: boresight_file is empty and boresight_rpy_deg is '
                '[0, 0, 0], so the LiDAR axes are taken as the IMU axes (identity). The '
                'cloud is only right if they are; calibrate with lidar_calibration and '
                'start with boresight_file:=~/.ros/accelcal/boresight.yaml')


class CloudAssemblerNode(Node):
    """Thin wiring around :class:`~accelcal_ros.lidar.assembler.CloudAssembler`."""

    def __init__(self):
        super().__init__('cloud_assembler')
        self.params = ParameterSet(self, SPECS, self._on_change)
        from accelcal_ros.frames import rotation_from_rpy_radians
        from accelcal_ros.lidar.assembler import CloudAssembler, RunningClock
        from accelcal_ros.lidar.boresight import load_boresight

        p = self.params
        problem = map_output_problem(p['output_file'], p['map_crs'])
        if problem:
            raise InputError(f'output_file: {problem}')
        boresight = (load_boresight(p['boresight_file']) if p['boresight_file'] else
                     rotation_from_rpy_radians(*np.radians(p['boresight_rpy_deg'])))
        self._core = CloudAssembler(boresight, p['lever_arm_m'], p['time_field'] or None,
                                    p['pose_buffer_s'], p['max_wait_s'], p['max_points'],
                                    max_gap_s=p['max_pose_gap_s'] or None)
        self._lock = threading.Lock()
        self._inbox: deque = deque()  # ('pose' | 'scan', ...) in arrival order
        self._running = RunningClock()  # the core's clock: a CPU stall does not count
        self._nav_frame = 'map'
        self._warned = set()
        self._drops = DropCounter(self)
        self._pub = self.create_publisher(PointCloud2, 'points_georef', p['queue_depth'])
        reliability = (ReliabilityPolicy.RELIABLE if p['points_reliable']
                       else ReliabilityPolicy.BEST_EFFORT)
        scans_qos = QoSProfile(depth=p['queue_depth'], reliability=reliability,
                               history=HistoryPolicy.KEEP_LAST)
        self.create_subscription(PointCloud2, 'points', self._on_cloud, scans_qos,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        self.create_subscription(Odometry, 'odom', self._on_odom, ODOMETRY_QUEUE_DEPTH,
                                 callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(Trigger, 'cloud_assembler/save', self._on_save)
        self.create_timer(0.02, self._on_timer, callback_group=MutuallyExclusiveCallbackGroup())
        self._no_boresight = not p['boresight_file'] and not any(p['boresight_rpy_deg'])
        self._last_save = ''
        self._diag_pub = diagnostics_publisher(self)
        self.create_timer(1.0, self._publish_diagnostics,
                          callback_group=MutuallyExclusiveCallbackGroup())
        self.get_logger().info('boresight rpy (deg) '
                               f'{np.round(np.degrees(_rpy(boresight)), 4).tolist()}, lever '
                               f'arm {p["lever_arm_m"]} m')
        self._map_origin = np.array(p['map_origin'], float) if p['map_origin'] else None
        if p['map_crs']:
            from accelcal_ros.lidar.map_output import origin_line

            self.get_logger().info(origin_line(self._map_origin, p['map_crs']))
        if self._no_boresight:
            self.get_logger().warning(NO_BORESIGHT)

    def _on_change(self, name, value):
        """Apply accepted run-time changes; raise InputError to reject one."""
        if name == 'output_file':
            problem = map_output_problem(value, self.params['map_crs'])
            if problem:
                raise InputError(problem)
        elif name == 'max_wait_s':
            with self._lock:
                self._core.max_wait_s = float(value)
        elif name == 'max_pose_gap_s':
            with self._lock:
                self._core.max_gap_s = float(value) or None

    def _publish_diagnostics(self):
        with self._lock:
            totals = dict(self._core.totals)
            summary = self._core.summary()
            rejected = self._core.rejected_poses
            waiting = self._core.waiting
        level, message = 0, summary
        if self._no_boresight:
            level, message = 1, f'identity boresight (none given); {summary}'
        if self._last_save.startswith('cannot write'):
            level, message = 2, self._last_save
        values = {'scans': totals['scans'], 'scans_waiting': waiting, 'points': totals['points'],
                  'points_georeferenced': totals['kept'],
                  'points_before_poses': totals['before'],
                  'points_after_poses': totals['after'],
                  'points_in_pose_gaps': totals['in_gap'],
                  'points_non_finite': totals['non_finite'], 'poses_rejected': rejected,
                  'boresight': 'identity (none given)' if self._no_boresight else 'given',
                  'output_file': self.params['output_file'], 'last_save': self._last_save}
        publish_diagnostics(self, self._diag_pub, [diagnostic_status(
            f'{self.get_name()}: georeferenced cloud', 'lidar', level, message, values)])

    def _warn_once(self, key, text):
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _on_odom(self, msg):
        pose = msg.pose.pose
        q = pose.orientation
        self._inbox.append(('pose', stamp_to_seconds(msg.header.stamp),
                            [pose.position.x, pose.position.y, pose.position.z],
                            [q.x, q.y, q.z, q.w], msg.header.frame_id))

    def _on_cloud(self, msg):
        try:
            cloud = pointcloud2_to_array(msg)
        except AccelcalError as exc:
            self._drops.drop('scans', f'scan dropped: {exc}')
            return
        self._inbox.append(('scan', stamp_to_seconds(msg.header.stamp), cloud))

    def _drain(self, now_s):
        """
        Hand the inbox to the core, in arrival order (with the lock held).

        Each item arrives at ``now_s`` on the core's clock (:class:`RunningClock`: at this
        tick, at most one tick after it came, so a scan waits that much longer).
        """
        while self._inbox:
            item = self._inbox.popleft()
            if item[0] == 'pose':
                _, stamp, position, quat, frame = item
                reason = self._core.add_pose(stamp, position, quat, now_s)
                if reason:
                    self._drops.drop('odometry', f'odometry rejected: {reason}')
                elif frame:
                    self._nav_frame = frame
                continue
            _, stamp, cloud = item
            try:
                self._core.add_scan(stamp, cloud, now_s)
            except AccelcalError as exc:
                self._drops.drop('scans', f'scan dropped: {exc}')

    def _on_timer(self):
        with self._lock:
            now = self._running.tick(time.monotonic())
            self._drain(now)
            done = self._core.process(now)
            frame = self.params['frame_id'] or self._nav_frame
        for nav, stats in done:
            if stats is None:
                self._drops.drop('scans', 'scan dropped: no odometry received yet')
                continue
            # said also of a scan no pose covers at all (nothing left of it to publish)
            if stats.before_span or stats.after_span or stats.in_gap:
                self._warn_once('span', f'{stats.summary()} (points outside the odometry '
                                        'are dropped, never extrapolated)')
            if not len(nav):
                continue
            if self.params['map_crs']:
                nav, frame = self._to_map(nav), self.params['frame_id'] or 'map'
            header = Header()
            header.frame_id = frame
            if len(nav):
                header.stamp = seconds_to_stamp(float(nav['timestamp'][0]), Time)
            self._pub.publish(array_to_pointcloud2(nav, PointCloud2, PointField, header))

    def _to_map(self, nav):
        from accelcal_ros.lidar.map_output import choose_origin, origin_line, shift_to_map

        if self._map_origin is None:
            self._map_origin = choose_origin([], [nav['x'][0], nav['y'][0], nav['z'][0]])
            self.get_logger().info(origin_line(self._map_origin, self.params['map_crs']))
        return shift_to_map(nav, self._map_origin)

    def _save(self):
        path = self.params['output_file']
        if not path:
            return False, 'output_file is empty: set it to a .ply or .pcd path'
        from accelcal_ros.lidar.map_output import write_map_cloud

        with self._lock:
            cloud = self._core.map_cloud()
            summary = self._core.summary()
        try:
            count = write_map_cloud(path, cloud, self.params['map_crs'],
                                    self.params['save_voxel_m'])
        except (AccelcalError, OSError) as exc:
            self._last_save = f'cannot write {path}: {exc}'
            return False, self._last_save
        self._last_save = f'wrote {count} points to {path}'
        return True, f'wrote {count} points to {path}; {summary}'

    def _on_save(self, request, response):
        response.success, response.message = self._save()
        if response.success:
            self.get_logger().info(response.message)
        else:
            self.get_logger().error(response.message)
        return response

    def close(self):
        """
        Write the accumulated cloud at shutdown (when output_file is set).

        What arrived and still waits (for odometry, or in the inbox) is georeferenced
        first with the poses there are; points they do not cover are counted as dropped.
        """
        if self.params['output_file']:
            with self._lock:
                now = self._running.tick(time.monotonic())
                self._drain(now)
                self._core.process(now, force=True)
            ok, message = self._save()
            if ok:
                self.get_logger().info(message)
            else:
                self.get_logger().error(message)


def _rpy(rotation):
    from accelcal_ros.frames import rpy_radians_from_rotation

    return rpy_radians_from_rotation(rotation)


def main(args=None):
    """Run the ``cloud_assembler`` node."""
    return run(CloudAssemblerNode, args, executor='events')
