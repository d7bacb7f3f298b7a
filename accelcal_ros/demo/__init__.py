"""
The main job (``run-demo``): every node on simulated sensors, in a real ROS 2 graph.

Stages run in order; each is a module here with ``run(ctx)`` (see :class:`DemoContext`).
"""
