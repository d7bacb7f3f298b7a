"""
The node executables' entry points (``setup.py`` console_scripts): BLAS in one thread.

Each entry point (:func:`run_node` of the executable's name) starts one node process, as
``ros2 run accelcal_ros <name>`` does: it calls :func:`prepare_node_process`, then imports
the node's module and runs its ``main()``. Like ``cli.py`` for the ``accelcal`` commands,
this dispatcher reaches every feature, importing a node's module only when it starts.

Why: OpenBLAS (numpy's, OpenCV 5's, and Debian's and Ubuntu's ``libopenblas``) hands a
product above about 262 k multiply-adds to its threads (an ``N x 3`` by ``3 x 3`` product
from ``N`` = 29 k points: a VLP-16 revolution), and those threads then spin, waiting for
the next one. Measured on this 2-core machine (``benchmarks/bench_blas_threads.py``): one
such product every 50 ms, as a node taking 20 scans a second does, kept a whole core busy
(101-105 % of a core against 1 % for a product below the size; 100-102 % at 10 a
second); with one BLAS thread it took 2-7 %. A robot computer's other nodes need that
core. So a node process starts with ``OPENBLAS_NUM_THREADS=1`` unless its environment
sets it (set it to use more); OpenBLAS reads it once, when numpy loads, which here is
after this module. The ``accelcal`` commands keep OpenBLAS's default: they run alone,
over recorded data.
"""
from functools import partial
import importlib
import os
import sys

BLAS_THREADS_VARIABLE = 'OPENBLAS_NUM_THREADS'
"""The variable OpenBLAS reads when it loads: its thread count."""
NODE_MODULES = {
    'imu_driver': 'accelcal_ros.driver.node',
    'calibration': 'accelcal_ros.calibration.node',
    'attitude': 'accelcal_ros.attitude.node',
    'stitcher': 'accelcal_ros.panorama.node',
    'p2p': 'accelcal_ros.p2p.node',
    'lidar_calibration': 'accelcal_ros.lidar.calibration_node',
    'rig_calibration': 'accelcal_ros.rig.node',
    'cloud_assembler': 'accelcal_ros.lidar.assembler_node',
    'calibration_frames': 'accelcal_ros.calibration_frames_node',
}
"""Executable name -> the module whose ``main()`` runs that node."""


def prepare_node_process() -> bool:
    """
    Set ``OPENBLAS_NUM_THREADS=1`` unless set; return False when it comes too late.

    Too late: numpy is already loaded (OpenBLAS read the variable then).
    """
    os.environ.setdefault(BLAS_THREADS_VARIABLE, '1')
    return 'numpy' not in sys.modules


def run_node(name: str) -> int:
    """Run node ``name`` (a key of :data:`NODE_MODULES`) in this process; its exit code."""
    prepare_node_process()
    return importlib.import_module(NODE_MODULES[name]).main()


# the console_scripts (setup.py): one per node, each ``run_node`` of its name
imu_driver = partial(run_node, 'imu_driver')
calibration = partial(run_node, 'calibration')
attitude = partial(run_node, 'attitude')
stitcher = partial(run_node, 'stitcher')
p2p = partial(run_node, 'p2p')
lidar_calibration = partial(run_node, 'lidar_calibration')
rig_calibration = partial(run_node, 'rig_calibration')
cloud_assembler = partial(run_node, 'cloud_assembler')
calibration_frames = partial(run_node, 'calibration_frames')
