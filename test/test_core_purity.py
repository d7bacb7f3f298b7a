"""
The pure core never imports rclpy or ROS message packages.

Only node modules, ``rosutil/``, the demo and ``*_ros.py`` adapters beside a simulator do.
"""
import ast
import os

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(REPO, 'accelcal_ros')
ROS_MODULES = ('rclpy', 'rcl_interfaces', 'std_msgs', 'std_srvs', 'sensor_msgs',
               'geometry_msgs', 'diagnostic_msgs', 'nav_msgs', 'visualization_msgs',
               'builtin_interfaces', 'launch', 'launch_ros')


def _is_ros_side(rel):
    base = os.path.basename(rel)
    return (base == 'node.py' or base.endswith(('_node.py', '_ros.py'))
            or rel.startswith('rosutil' + os.sep) or rel.startswith('demo' + os.sep))


def test_core_modules_do_not_import_ros():
    """Every module outside nodes, rosutil/ and demo/ is free of ROS imports."""
    offenders = []
    for dirpath, _, files in os.walk(PACKAGE):
        for name in files:
            if not name.endswith('.py'):
                continue
            path = os.path.join(dirpath, name)
            rel = os.path.relpath(path, PACKAGE)
            if _is_ros_side(rel):
                continue
            tree = ast.parse(open(path).read(), path)
            for item in ast.walk(tree):
                names = []
                if isinstance(item, ast.Import):
                    names = [a.name for a in item.names]
                elif isinstance(item, ast.ImportFrom) and item.module and item.level == 0:
                    names = [item.module]
                for mod in names:
                    if mod.split('.')[0] in ROS_MODULES:
                        offenders.append(f'{rel}: imports {mod}')
    assert not offenders, '\n'.join(offenders)
