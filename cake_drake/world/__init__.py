"""The world: the scene (table, Panda, cubes) built from ``models/`` (``scene.py``), the
cameras and the renderer, the cubes placed from a PDDL state and read back as PDDL facts
(``facts.py``), and the faults a scenario injects (``faults.py``). ``python -m
cake_drake.world`` lays a problem out (its command module lays it out and renders it).
"""
