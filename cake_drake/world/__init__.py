"""The world: the scene (table, Panda, cubes) built from ``models/`` (``scene.py``), the
cameras (``cameras.py``) and the renderer (``render.py``), the cubes placed from a PDDL
state and read back as PDDL facts (``facts.py``), and the faults a scenario injects
(``faults.py``). ``python -m cake_drake.world`` lays a problem out and renders it (its
command module does, which the library never imports).
"""
