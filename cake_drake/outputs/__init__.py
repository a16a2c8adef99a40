"""What a run shows a person: the output transaction (``files``), plots (``plots``), the
picture of the final world and ``cake.png`` (``cake``: the run's layers), the summary and
report (``report``), what the cameras saw (``perception``: ``perception.png``), the
Meshcat replay (``replay``), the Diagram drawn with Graphviz (``graph``), and the helper
processes that draw while the world is simulated (``worker``)."""
