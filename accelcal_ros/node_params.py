"""
Which :class:`~accelcal_ros.paramspec.ParamSpec` list each node executable declares (pure).

The specs are the one source of every parameter's name, type and default: the config
dataclasses of the cores are read by the specs (or feed them), ``config/<node>.yaml``
lists the same names with the same defaults (checked by ``test/test_node_params.py``),
and the graph test asks every running node for every parameter it declared.
"""
import importlib
from typing import Dict, Tuple

from accelcal_ros.paramspec import ParamSpec

NODE_PARAMS: Dict[str, Tuple[str, str]] = {
    'imu_driver': ('accelcal_ros.driver.params', 'DRIVER_PARAMS'),
    'calibration': ('accelcal_ros.calibration.params', 'CALIBRATION_PARAMS'),
    'attitude': ('accelcal_ros.attitude.params', 'ATTITUDE_PARAMS'),
    'stitcher': ('accelcal_ros.panorama.roi_params', 'STITCHER_WITH_ROI_PARAMS'),
    'p2p': ('accelcal_ros.p2p.params', 'P2P_PARAMS'),
    'lidar_calibration': ('accelcal_ros.lidar.params', 'LIDAR_CALIBRATION_PARAMS'),
    'cloud_assembler': ('accelcal_ros.lidar.params', 'CLOUD_ASSEMBLER_PARAMS'),
    'rig_calibration': ('accelcal_ros.rig.params', 'RIG_CALIBRATION_PARAMS'),
    'calibration_frames': ('accelcal_ros.frame_tree', 'CALIBRATION_FRAMES_PARAMS'),
}
"""Node (and executable) name -> (module, attribute) of its ParamSpec list."""


def node_specs(node: str) -> Tuple[ParamSpec, ...]:
    """Return the ParamSpecs node ``node`` declares (KeyError for an unknown node)."""
    module, attribute = NODE_PARAMS[node]
    return tuple(getattr(importlib.import_module(module), attribute))
