"""Geometric layer: where the hand goes.

A ground action and the measured world become named waypoints (``waypoints.py``), the
waypoints joint targets by inverse kinematics (``ik.py``, ``solve.py``), the targets a
timed, blended joint trajectory (``trajectory.py``); ``collisions.py``, ``free_space.py``
and ``planners.py`` keep the moves out of the table, the towers and the robot itself.
Plain functions over plain data: the Diagram's ``WaypointIk`` (``systems/``) calls them.
"""
