"""
Shared pytest fixtures.

Every test session gets its own ``ROS_DOMAIN_ID`` (allocated with a lock file so
concurrent runs on one machine never share a domain) and localhost-only discovery, set
before anything initialises rclpy. Graph tests use :class:`graph_harness.graph.Graph` to start
the installed node executables as separate processes and talk to them with rclpy.
"""
import os

from graph_harness.domain import allocate_domain_id
import pytest

_DOMAIN = allocate_domain_id()
os.environ['ROS_DOMAIN_ID'] = str(_DOMAIN.domain_id)
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'


@pytest.fixture(scope='session')
def ros_domain_id():
    """Return the ROS domain ID of this test session."""
    return _DOMAIN.domain_id


@pytest.fixture
def graph(tmp_path):
    """
    Start a probe node in a fresh rclpy context, plus a launcher for installed nodes.

    Yields :class:`graph_harness.graph.Graph`; every process it started is stopped
    afterwards.
    """
    from graph_harness.graph import Graph

    g = Graph(log_dir=tmp_path, name='test_probe')
    try:
        yield g
    finally:
        g.close()
