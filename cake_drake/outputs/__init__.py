"""What a run shows a person: the output transaction (``files.py``), plots, the picture of
the final world, ``cake.png`` (the run's layers), the summary and report, the Meshcat
replay, the Diagram drawn with Graphviz, and the helper processes that draw while the
world is simulated (``worker.py``).
"""
