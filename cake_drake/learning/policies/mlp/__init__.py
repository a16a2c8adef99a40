"""A small state policy registered with LeRobot as the policy type ``cake_mlp``.

LeRobot finds a policy type that is not its own by a naming convention: the configuration
class ``XConfig`` in a module ``configuration_*``, the policy ``XPolicy`` in ``modeling_*``
beside it and ``make_<type>_pre_post_processors`` in ``processor_*`` (here
``configuration_mlp``, ``modeling_mlp`` and ``processor_mlp``). Importing
``configuration_mlp`` registers the type, after which LeRobot's own training loop,
checkpoints and loaders treat it as any of theirs (``python -m cake_drake.train --policy
mlp``). ``features`` says what it reads, ``acting`` acts with it in NumPy, and ``network`` is
the same network in torch alone, which a run acts with: importing
this package imports neither (LeRobot's configurations cost seconds).
"""
