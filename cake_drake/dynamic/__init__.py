"""Dynamic layer: how hard the joints push.

``controllers.py`` holds the controllers a scenario chooses (computed torque with Drake's
``InverseDynamicsController``, the plant's joint PD, a torque-level PID, or yours through
the plug-in door); ``residual.py`` the learned residual torque beside computed torque and
its one loader; ``reference.py`` a recorded trajectory replayed as the reference (and the
reference ports every source of one has); ``analysis.py`` what the logs say of tracking.
"""
