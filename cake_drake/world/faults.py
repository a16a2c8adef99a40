"""Faults: the world disagreeing with the plan, on purpose and reproducibly.

A scenario's ``faults:`` list (``--fault SPEC`` on the command line, repeatable):

* ``!Slip {action: K}`` (``slip:K``) - during the K-th executed action the fingers let go
  of the cube they carry (in its lift or transport phase);
* ``!Knock {cube: C, time: T}`` (``knock:C@T``) - at simulated time T a short horizontal
  push at C's centre (0.8 N for 0.1 s, through the plant's external-force input),
  towards the robot: C slides out and whatever stands on it falls;
* ``!Move {cube: C, time: T, x: X, y: Y}`` (``move:C@T:X,Y``) - at time T, C is taken
  away and set down on the table at (X, Y) in the world frame, as a person would;
* ``!RandomFault {seed: S}`` (``random:S``) - one of the above, its kind, cube, time or
  action drawn from S.

Everything is checked before the simulation starts: the cube exists, times are finite
and >= 0, K is an action of the plan, (X, Y) is on the table and off the robot's base.
"""

import math
import random
from dataclasses import dataclass

import numpy as np
from pydrake.common.value import AbstractValue
from pydrake.math import RigidTransform, RollPitchYaw
from pydrake.multibody.math import SpatialForce
from pydrake.multibody.plant import ExternallyAppliedSpatialForce
from pydrake.multibody.tree import BodyIndex
from pydrake.systems.framework import BasicVector, LeafSystem

from cake_drake.errors import InputError

#: The table top (world frame, m): x from -0.25 to 0.95, y from -0.6 to 0.6, z = 0.
TABLE_X = (-0.25, 0.95)
TABLE_Y = (-0.6, 0.6)
BASE_CLEARANCE = 0.3  # m: nothing is set down closer than this to the robot's base
LIFT, TRANSPORT = 3, 4  # phase indices (cake_drake.formats.PHASE_NAMES)


@dataclass
class Slip:
    action: int = 1  # the K-th executed action (1-based)


@dataclass
class Knock:
    cube: str = ""
    time: float = 0.0  # s, simulated
    force: float = 0.8  # N, horizontal, towards the robot (the cube weighs 0.5 N)
    duration: float = 0.1  # s


@dataclass
class Move:
    cube: str = ""
    time: float = 0.0  # s, simulated
    x: float = 0.0  # m, world frame
    y: float = 0.0


@dataclass
class RandomFault:
    seed: int | None = None  # None: the scenario's seed (so a sweep's seeds draw faults)


FaultConfig = Slip | Knock | Move | RandomFault


def parse_fault(spec: str) -> FaultConfig:
    """``slip:K``, ``knock:CUBE@T``, ``move:CUBE@T:X,Y`` or ``random:SEED``."""
    kind, _, rest = spec.partition(":")
    usage = "a fault is slip:K, knock:CUBE@T, move:CUBE@T:X,Y or random:SEED"
    try:
        if kind == "slip":
            return Slip(int(rest))
        if kind == "knock":
            cube, _, t = rest.partition("@")
            return Knock(cube, float(t))
        if kind == "move":
            cube, _, where = rest.partition("@")
            t, _, xy = where.partition(":")
            x, y = xy.split(",")
            return Move(cube, float(t), float(x), float(y))
        if kind == "random":
            return RandomFault(int(rest))
    except ValueError:
        raise InputError(f"--fault {spec!r}: cannot read it; {usage}") from None
    raise InputError(f"--fault {spec!r}: unknown kind {kind!r}; {usage}")


def _place_ok(x: float, y: float) -> bool:
    on_table = (
        TABLE_X[0] + 0.03 <= x <= TABLE_X[1] - 0.03 and TABLE_Y[0] + 0.03 <= y <= TABLE_Y[1] - 0.03
    )
    return on_table and math.hypot(x, y) >= BASE_CLEARANCE


def check_faults(faults, blocks, n_actions: int) -> None:
    """Refuse faults that cannot happen, before simulating; one line naming the fault."""
    for f in faults:
        if isinstance(f, Slip) and not 1 <= f.action <= n_actions:
            raise InputError(f"fault slip:{f.action}: the plan has actions 1 to {n_actions}")
        if isinstance(f, Knock | Move):
            if f.cube not in blocks:
                raise InputError(
                    f"fault on cube {f.cube!r}: no such cube (the cubes: {', '.join(blocks)})"
                )
            if not (math.isfinite(f.time) and f.time >= 0):
                raise InputError(f"fault on {f.cube} at time {f.time}: times are >= 0 s")
        if isinstance(f, Knock) and not (0 < f.force <= 20 and 0 < f.duration <= 1):
            raise InputError(f"knock on {f.cube}: force 0-20 N, duration 0-1 s")
        if isinstance(f, Move) and not _place_ok(f.x, f.y):
            raise InputError(
                f"move {f.cube} to ({f.x}, {f.y}): not on the table (x {TABLE_X[0]} to "
                f"{TABLE_X[1]} m, y {TABLE_Y[0]} to {TABLE_Y[1]} m) or within "
                f"{BASE_CLEARANCE} m of the robot's base"
            )


def resolve_random(
    fault: RandomFault, blocks, n_actions: int, makespan: float, seed: int = 0, avoid=()
) -> FaultConfig:
    """The fault a seed stands for (the fault's own, else ``seed``): kind, cube, time
    (within the first 80 % of the expected run) or action, and where a moved cube goes
    (on the table, clear of the table slots in ``avoid`` by 10 cm: a cube set down onto
    a tower would be a different fault)."""
    rng = random.Random(f"fault-{seed if fault.seed is None else fault.seed}")
    kind = rng.choice(["slip", "knock", "move"])
    if kind == "slip":
        return Slip(rng.randint(1, n_actions))
    cube = rng.choice(sorted(blocks))
    t = round(rng.uniform(0.1, 0.8) * makespan, 2)
    if kind == "knock":
        return Knock(cube, t)
    while True:  # a free spot on the table within the arm's comfortable reach
        r, a = rng.uniform(0.45, 0.65), rng.uniform(-1.0, 1.0)
        x, y = round(r * math.cos(a), 3), round(r * math.sin(a), 3)
        if _place_ok(x, y) and all(math.hypot(x - sx, y - sy) > 0.1 for sx, sy in avoid):
            return Move(cube, t, x, y)


class SlipFingers(LeafSystem):
    """Passes the finger command through, but opens the fingers while action K carries.

    .. pydrake_system::

        name: SlipFingers
        input_ports:
        - finger_state
        - labels
        output_ports:
        - finger_command
    """

    def __init__(self, actions: list[int]) -> None:
        super().__init__()
        self._slips = {k - 1 for k in actions}  # global 0-based action indices
        self._command = self.DeclareVectorInputPort("finger_state", BasicVector(4))
        self._labels = self.DeclareVectorInputPort("labels", BasicVector(2))
        self.DeclareVectorOutputPort("finger_command", BasicVector(4), self._calc)

    def _calc(self, context, output) -> None:
        phase, action = self._labels.Eval(context)
        if int(round(action)) in self._slips and int(round(phase)) in (LIFT, TRANSPORT):
            output.SetFromVector([0.04, 0.04, 0.0, 0.0])
        else:
            output.SetFromVector(self._command.Eval(context))


class Pusher(LeafSystem):
    """Horizontal pushes on cubes at given times (the plant's applied spatial forces).

    .. pydrake_system::

        name: Pusher
        output_ports:
        - forces
    """

    def __init__(self, pushes: list[tuple[int, float, float, float]]) -> None:
        """``pushes``: (body index, start time, duration, force) each."""
        super().__init__()
        self._pushes = pushes
        self._poses = self.DeclareAbstractInputPort(
            "body_poses", AbstractValue.Make([RigidTransform()])
        )
        self.DeclareAbstractOutputPort(
            "forces", lambda: AbstractValue.Make([ExternallyAppliedSpatialForce()]), self._calc
        )

    def _calc(self, context, output) -> None:
        t = context.get_time()
        out = []
        for body, start, duration, force in self._pushes:
            if start <= t < start + duration:
                p = self._poses.Eval(context)[body].translation()
                # Towards the robot: what falls lands in front of the towers, within reach
                # and away from the neighbouring slots (sideways it would fall onto them).
                away = -np.array([p[0], p[1], 0.0]) / max(np.hypot(p[0], p[1]), 1e-9)
                f = ExternallyAppliedSpatialForce()
                f.body_index = BodyIndex(body)
                f.p_BoBq_B = np.zeros(3)  # at its centre: it slides out, what stands on it falls
                f.F_Bq_W = SpatialForce(np.zeros(3), force * away)
                out.append(f)
        output.set_value(out)


def move_cube(plant, plant_context, body, x: float, y: float) -> None:
    """Set a cube down, at rest, on the table at (x, y)."""
    plant.SetFreeBodyPose(
        plant_context, body, RigidTransform(RollPitchYaw(0, 0, math.atan2(y, x)), [x, y, 0.02])
    )
    from pydrake.multibody.math import SpatialVelocity

    plant.SetFreeBodySpatialVelocity(plant_context, body, SpatialVelocity(np.zeros(3), np.zeros(3)))
