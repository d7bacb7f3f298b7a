"""
The calibration's coverage as visualization_msgs/MarkerArray (ROS side of ``calibration``).

Directions are those the coverage uses (:mod:`accelcal_ros.calibration.coverage`): the unit
specific force of each capture in the sensor frame (REP-145, the up direction; gravity
points the other way), drawn on the unit sphere around the IMU frame's origin:

* namespace ``captured``: one sphere per capture (id = capture index), green;
* ``missing``: the recommended 12 directions not yet within the coverage radius, grey;
* ``next``: an arrow from the origin to the next suggested orientation (the first of the
  status's ``hint``), orange; absent when nothing is left to suggest.

Every array starts with a DELETEALL marker, so rviz drops what a previous array showed.
"""
from accelcal_ros.calibration.coverage import (missing_directions, suggested_directions,
                                               unit_directions)
from geometry_msgs.msg import Point
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

_GREEN = ColorRGBA(r=0.2, g=0.8, b=0.2, a=1.0)
_GREY = ColorRGBA(r=0.6, g=0.6, b=0.6, a=0.6)
_ORANGE = ColorRGBA(r=1.0, g=0.55, b=0.0, a=1.0)


def _sphere(header, ns, index, direction, color, size):
    marker = Marker(header=header, ns=ns, id=index, type=Marker.SPHERE, action=Marker.ADD)
    p = marker.pose.position
    p.x, p.y, p.z = (float(v) for v in direction)
    marker.pose.orientation.w = 1.0
    marker.scale.x = marker.scale.y = marker.scale.z = size
    marker.color = color
    return marker


def coverage_markers(header, captured, radius_deg, suggest):
    """
    Return the MarkerArray of ``captured`` (N, 3) specific-force means.

    ``radius_deg`` is the coverage radius; ``suggest`` False (the session is done or not
    running) leaves out the missing directions and the next suggestion.
    """
    array = MarkerArray()
    array.markers.append(Marker(header=header, action=Marker.DELETEALL))
    units = unit_directions(captured) if len(captured) else []
    for index, direction in enumerate(units):
        array.markers.append(_sphere(header, 'captured', index, direction, _GREEN, 0.1))
    if not suggest:
        return array
    for index, direction in enumerate(missing_directions(captured, radius_deg)):
        array.markers.append(_sphere(header, 'missing', index, direction, _GREY, 0.07))
    nxt = suggested_directions(captured, 1)
    if nxt:
        arrow = Marker(header=header, ns='next', id=0, type=Marker.ARROW, action=Marker.ADD,
                       text=nxt[0][0])
        arrow.points = [Point(), Point(x=float(nxt[0][1][0]), y=float(nxt[0][1][1]),
                                       z=float(nxt[0][1][2]))]
        arrow.pose.orientation.w = 1.0
        arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.04, 0.08, 0.1
        arrow.color = _ORANGE
        array.markers.append(arrow)
    return array
