"""Parameters of the levelled views the ``stitcher`` node grows (pure: checked without ROS)."""
from accelcal_ros.errors import InputError
from accelcal_ros.panorama.params import STITCHER_PARAMS
from accelcal_ros.panorama.view_pose import MAX_VIEW_SIDE_PX, MIN_VIEW_SIDE_PX
from accelcal_ros.panorama.view_set import parse_view_entry, repeated_names_reason
from accelcal_ros.paramspec import ParamSpec

MAX_VIEWS_LIMIT = 64
"""Largest value of ``roi_max_views``."""


def _entries_reason(values):
    names = []
    for entry in values:
        try:
            names.append(parse_view_entry(entry)[0])
        except InputError as exc:
            return str(exc)
    return repeated_names_reason(names)


ROI_PARAMS = [
    ParamSpec('roi_views', [], 'levelled views published as roi/<name>/image and '
              'roi/<name>/camera_info: NAME or NAME:AZIMUTH,ELEVATION,FOV_H (deg; azimuth 0 '
              '= panorama centre, positive right; elevation positive up; fov_h in (0, 180)); '
              'set at run time to add, remove or point views', kind='string_array',
              validator=_entries_reason),
    ParamSpec('roi_width', 1280, 'width of each view', minimum=MIN_VIEW_SIDE_PX,
              maximum=MAX_VIEW_SIDE_PX, unit='px', read_only=True),
    ParamSpec('roi_height', 720, 'height of each view', minimum=MIN_VIEW_SIDE_PX,
              maximum=MAX_VIEW_SIDE_PX, unit='px', read_only=True),
    ParamSpec('roi_max_views', 8, 'most views at once (more are refused with the reason)',
              minimum=1, maximum=MAX_VIEWS_LIMIT, read_only=True),
    ParamSpec('roi_serve_port', 0, 'serve the live views in a browser on this TCP port, one '
              'view per tab (0: off; the page of accelcal serve)', minimum=0, maximum=65535,
              read_only=True),
    ParamSpec('roi_serve_host', '127.0.0.1', 'address the browser server listens on (any '
              'address but loopback requires roi_serve_token)', read_only=True),
    ParamSpec('roi_serve_token', '', 'token every browser request must carry (?token=...); '
              'required when roi_serve_host is not a loopback address', read_only=True),
]
"""The views' parameters (declared by :class:`~.roi_node.RoiViews` on the stitcher)."""

STITCHER_WITH_ROI_PARAMS = list(STITCHER_PARAMS) + ROI_PARAMS
"""Every parameter the ``stitcher`` executable declares (see config/stitcher.yaml)."""
