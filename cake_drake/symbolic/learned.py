"""The learned planner: a relational network that picks the next ground action.

A Blocksworld state and its goal are read through the domain's roles
(:mod:`.roles`), so every naming the classical planners read (the exercise's,
the IPC's, typed and renamed variants) reaches the network as the same
canonical facts. The network is object-centric: each block is a node with a
few unary facts (on the table, clear, held, and the same in the goal), the
blocks are linked by the ``on`` relation, the goal's ``on`` and the goal
``on`` facts already true, both ways, and one shared layer is repeated as
many times as the problem's tallest tower (current or goal) is high, plus
two. Nothing in it counts the blocks or knows their names: the same weights
read 3 blocks or 50, and renaming or reordering the blocks changes nothing.

A plan is made by rolling the network's choices out in the symbolic model:
each step scores the applicable actions and takes the best one; a domain's static
preconditions (the renamed variant's ``(cube ?c)``) are applicability too, so an action
the problem never allows is never offered, and a goal that only such actions reach is
the classical planners' "no plan exists", with their proof. A state seen
twice (a loop), a step budget of four actions per block (what moving every
block twice costs) or the time limit ends it with :class:`NoPlanError`
naming the reason; the planner registry validates every plan it returns.

Inference is plain numpy (planning needs no torch); training lives in
:mod:`cake_drake.learning.training.planner`. A checkpoint is a folder with
``planner.json`` (what it is, its architecture, how it was trained) and
``weights.npz``, read by :func:`load_planner` alone, which checks the two
against each other before anything plans with them.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from threadpoolctl import threadpool_limits

from cake_drake.errors import InputError, NoPlanError
from cake_drake.formats import WeightsFolder, check_format
from cake_drake.paths import MODELS_DIR, portable_path, resolve_path
from cake_drake.symbolic.diagnose import diagnose
from cake_drake.symbolic.grounding import check_action, ground_all, relaxed_reachable
from cake_drake.symbolic.pddl import GroundAction, Problem
from cake_drake.symbolic.roles import PICK, PLACE, blocksworld_roles, blocksworld_view

#: What a learned planner's ``planner.json`` says it is.
KIND = "cake_drake.learned_planner"
FORMAT = 1
#: The shipped checkpoint, ``--planner learned``.
SHIPPED = MODELS_DIR / "planners" / "blocks"
#: ``--planner learned@DIR`` plans with another checkpoint (a folder): ``@`` cannot appear in
#: a Python module's name, so it is never read as a ``module:attribute`` plug-in.
PREFIX = "learned@"

#: Per block, in this order: the network's unary inputs.
NODE_FEATURES = (
    "on-table",
    "clear",
    "holding",
    "goal on-table",
    "goal clear",
    "goal holding",
    "goal on something",
    "goal something on it",
    "on its goal block",
    "on the table as in the goal",
)
#: Per state: the network's global inputs.
GLOBAL_FEATURES = ("arm-empty", "goal arm-empty")
#: Binary relations, each read both ways (what a block is on, what is on it).
RELATIONS = ("on", "goal on", "on and goal on")
#: Per (block, other block) of a binary action: the atoms that link the two, which the
#: binary head reads besides the two blocks' embeddings.
PAIR_FEATURES = ("on", "goal on", "other on block", "other goal on block")
#: Action kinds the heads score: unary (block) and binary (block, other block).
UNARY_HEADS = ("pick-up", "put-down")
BINARY_HEADS = ("unstack", "stack")

TABLE, HELD = -1, -2


def weight_shapes(width: int) -> dict[str, tuple[int, ...]]:
    """Every weight array a checkpoint of ``width`` holds, with its shape."""
    w, f, g, r = width, len(NODE_FEATURES), len(GLOBAL_FEATURES), 2 * len(RELATIONS)
    z = w + f + r * w + g
    return {
        "enc_w": (f, w),
        "enc_b": (w,),
        "upd1_w": (z, w),
        "upd1_b": (w,),
        "upd2_w": (w, w),
        "upd2_b": (w,),
        "norm_g": (w,),
        "norm_b": (w,),
        "un1_w": (w, w),
        "un1_b": (w,),
        "un2_w": (w, len(UNARY_HEADS)),
        "un2_b": (len(UNARY_HEADS),),
        "bi_x": (w, w),
        "bi_y": (w, w),
        "bi_p": (len(PAIR_FEATURES), w),
        "bi1_b": (w,),
        "bi2_w": (w, len(BINARY_HEADS)),
        "bi2_b": (len(BINARY_HEADS),),
    }


# --------------------------------------------------------------------------- the state


@dataclass(frozen=True)
class Graph:
    """A state and goal as the network reads them (blocks by index).

    ``below[i]`` is the index of the block that block i is on, :data:`TABLE` or
    :data:`HELD`; ``goal_below[i]`` the same in the goal, or None-like -3 when the
    goal does not say where block i goes.
    """

    below: tuple[int, ...]
    goal_below: tuple[int, ...]
    goal_clear: tuple[bool, ...]
    goal_held: tuple[bool, ...]
    goal_arm_empty: bool


NO_GOAL = -3


def _chain(below: tuple[int, ...]) -> int:
    """The tallest tower's height under ``below`` (cycles, in an impossible goal, cut at n)."""
    n, best = len(below), 0
    for i in range(n):
        h, j = 1, below[i]
        while j >= 0 and h <= n:
            h, j = h + 1, below[j]
        best = max(best, h)
    return best


def rounds(graph: Graph) -> int:
    """How many times the shared layer runs: the tallest tower (current or goal) plus two."""
    return max(_chain(graph.below), _chain(graph.goal_below)) + 2


def features(graph: Graph) -> tuple[np.ndarray, np.ndarray, list[tuple[np.ndarray, np.ndarray]]]:
    """(node features n x F, global features G, per relation (x indices, y indices))."""
    below, gb = np.asarray(graph.below), np.asarray(graph.goal_below)
    n = len(below)
    has_above = np.zeros(n, bool)
    has_above[below[below >= 0]] = True
    held = below == HELD
    goal_above = np.zeros(n, bool)
    goal_above[gb[gb >= 0]] = True
    x0 = np.stack(
        [
            below == TABLE,
            ~has_above & ~held,
            held,
            gb == TABLE,
            np.asarray(graph.goal_clear, bool),
            np.asarray(graph.goal_held, bool),
            gb >= 0,
            goal_above,
            (below >= 0) & (below == gb),
            (below == TABLE) & (gb == TABLE),
        ],
        axis=1,
    ).astype(np.float64)
    g = np.array([not held.any(), graph.goal_arm_empty], np.float64)
    idx = np.arange(n)
    on = below >= 0
    gon = gb >= 0
    both = on & (below == gb)
    rel = [(idx[m], b[m]) for m, b in ((on, below), (gon, gb), (both, below))]
    return x0, g, rel


def pair_features(graph: Graph, xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """:data:`PAIR_FEATURES` of each pair (xs[k], ys[k]), as a len(xs) x 4 array."""
    below, gb = np.asarray(graph.below), np.asarray(graph.goal_below)
    return np.stack([below[xs] == ys, gb[xs] == ys, below[ys] == xs, gb[ys] == xs], axis=1).astype(
        np.float64
    )


def applicable(below: tuple[int, ...]) -> list[tuple[str, int, int]]:
    """The actions applicable in ``below``: (head, block, other block or -1)."""
    n = len(below)
    covered = {j for j in below if j >= 0}
    held = [i for i in range(n) if below[i] == HELD]
    clear = [i for i in range(n) if i not in covered and below[i] != HELD]
    if held:
        x = held[0]
        return [("put-down", x, -1)] + [("stack", x, y) for y in clear]
    return [("pick-up", x, -1) if below[x] == TABLE else ("unstack", x, below[x]) for x in clear]


def apply(below: tuple[int, ...], action: tuple[str, int, int]) -> tuple[int, ...]:
    """The state after ``action`` (one of :func:`applicable`'s)."""
    kind, x, y = action
    out = list(below)
    out[x] = HELD if kind in ("pick-up", "unstack") else (TABLE if kind == "put-down" else y)
    return tuple(out)


def satisfied(below: tuple[int, ...], graph: Graph) -> bool:
    """True when ``below`` meets every goal fact of ``graph``."""
    n = len(below)
    covered = {j for j in below if j >= 0}
    for i in range(n):
        if graph.goal_below[i] != NO_GOAL and below[i] != graph.goal_below[i]:
            return False
        if graph.goal_held[i] and below[i] != HELD:
            return False
        if graph.goal_clear[i] and (i in covered or below[i] == HELD):
            return False
    return not (graph.goal_arm_empty and HELD in below)


# --------------------------------------------------------------------------- the network


def _relu(a: np.ndarray) -> np.ndarray:
    return np.maximum(a, 0.0)


def _norm(h: np.ndarray, gain: np.ndarray, bias: np.ndarray) -> np.ndarray:
    mu = h.mean(axis=-1, keepdims=True)
    var = h.var(axis=-1, keepdims=True)
    return (h - mu) / np.sqrt(var + 1e-5) * gain + bias


def embed(w: dict[str, np.ndarray], graph: Graph) -> np.ndarray:
    """The blocks' embeddings after :func:`rounds` passes of the shared layer."""
    x0, g, rel = features(graph)
    n, f = x0.shape
    h = _relu(x0 @ w["enc_w"] + w["enc_b"])
    width = h.shape[1]
    # The update's input, [h, x0, (down, up) per relation, g], kept in one array whose
    # constant columns are written once.
    z = np.zeros((n, width + f + 2 * len(rel) * width + len(g)), np.float64)
    z[:, width : width + f] = x0
    z[:, -len(g) :] = g
    # Each relation is a function both ways in a physical state and a consistent goal:
    # then plain assignment sums; otherwise (an impossible goal) add each message.
    unique = [len(set(xs.tolist())) == len(xs) and len(set(ys.tolist())) == len(ys)
              for xs, ys in rel]  # fmt: skip
    for _ in range(rounds(graph)):
        z[:, :width] = h
        col = width + f
        for (xs, ys), one in zip(rel, unique, strict=True):
            down, up = z[:, col : col + width], z[:, col + width : col + 2 * width]
            down[:] = 0.0
            up[:] = 0.0
            if one:
                down[xs] = h[ys]
                up[ys] = h[xs]
            else:
                np.add.at(down, xs, h[ys])
                np.add.at(up, ys, h[xs])
            col += 2 * width
        delta = _relu(z @ w["upd1_w"] + w["upd1_b"]) @ w["upd2_w"] + w["upd2_b"]
        h = _norm(h + delta, w["norm_g"], w["norm_b"])
    return h


def scores(w: dict[str, np.ndarray], graph: Graph, actions) -> np.ndarray:
    """The network's score of each of ``actions`` (higher is better) in ``graph``."""
    h = embed(w, graph)
    un = _relu(h @ w["un1_w"] + w["un1_b"]) @ w["un2_w"] + w["un2_b"]
    out = np.empty(len(actions))
    pairs = [k for k, (_, _, y) in enumerate(actions) if y >= 0]
    for k, (kind, x, y) in enumerate(actions):
        if y < 0:
            out[k] = un[x, UNARY_HEADS.index(kind)]
    if pairs:
        xs = np.array([actions[k][1] for k in pairs])
        ys = np.array([actions[k][2] for k in pairs])
        heads = np.array([BINARY_HEADS.index(actions[k][0]) for k in pairs])
        pf = pair_features(graph, xs, ys)
        hidden = _relu(h[xs] @ w["bi_x"] + h[ys] @ w["bi_y"] + pf @ w["bi_p"] + w["bi1_b"])
        out[pairs] = (hidden @ w["bi2_w"] + w["bi2_b"])[np.arange(len(pairs)), heads]
    return out


# --------------------------------------------------------------------------- checkpoints


@dataclass(frozen=True)
class LearnedPlanner:
    """A checked checkpoint: its folder, its ``planner.json`` and its weights."""

    path: Path
    config: dict
    weights: dict[str, np.ndarray]

    @property
    def width(self) -> int:
        return int(self.config["architecture"]["width"])


def _check_config(cfg_path: Path, cfg: dict) -> dict:
    if cfg.get("kind") != KIND:
        raise READER.bad(cfg_path, f"field 'kind' is {cfg.get('kind')!r}, expected {KIND!r}")
    check_format(cfg, cfg_path, (FORMAT,))
    arch = cfg.get("architecture")
    if not isinstance(arch, dict):
        raise READER.bad(cfg_path, "field 'architecture' is missing or not a mapping")
    width = arch.get("width")
    if not isinstance(width, int) or isinstance(width, bool) or not 1 <= width <= 1024:
        raise READER.bad(cfg_path, f"field 'architecture.width' is {width!r}; an integer 1 to 1024")
    for key, expected in (
        ("node_features", NODE_FEATURES),
        ("global_features", GLOBAL_FEATURES),
        ("relations", RELATIONS),
        ("pair_features", PAIR_FEATURES),
    ):
        if arch.get(key) != list(expected):
            raise READER.bad(
                cfg_path,
                f"field 'architecture.{key}' is {arch.get(key)!r}; this version reads "
                f"{list(expected)}",
            )
    return cfg


#: The checked reader of a learned planner's folder (:class:`cake_drake.formats.WeightsFolder`).
READER = WeightsFolder(
    "learned planner checkpoint", "planner.json", _check_config,
    lambda cfg: weight_shapes(cfg["architecture"]["width"]),
)  # fmt: skip


def load_planner(path: str | Path) -> LearnedPlanner:
    """Read and check a learned planner's folder; :class:`InputError` naming the file and field.

    ``planner.json`` must say it is a learned planner of this format, with an
    architecture this version reads; ``weights.npz`` must hold exactly the arrays
    that architecture needs, with their shapes, all finite numbers, read by the project's
    one checked reader (:class:`cake_drake.formats.WeightsFolder`). Checked checkpoints
    are remembered by their files' bytes (a digest), never by their names or times.
    """
    folder = Path(path)
    return _load_checked(folder, READER.digest(folder))


@lru_cache(maxsize=8)
def _load_checked(folder: Path, digest: str) -> LearnedPlanner:
    del digest  # the cache's key: the same bytes are the same checkpoint
    return LearnedPlanner(folder, *READER.read(folder))


def checkpoint_of(spec: str) -> Path:
    """The folder a planner name names: ``learned`` the shipped one, ``learned@DIR`` DIR."""
    if spec == "learned":
        return SHIPPED
    folder = spec[len(PREFIX) :] if spec.startswith(PREFIX) else ""
    if folder:
        return resolve_path(folder)
    raise InputError(f"planner {spec!r}: a learned planner is 'learned' or 'learned@DIR'")


def is_learned(spec: str) -> bool:
    """True when ``spec`` names a learned planner (``learned`` or ``learned@DIR``)."""
    return spec == "learned" or spec.startswith(PREFIX)


# --------------------------------------------------------------------------- planning


def read_problem(problem: Problem) -> tuple[list[str], Graph]:
    """The problem's blocks and its initial state and goal as a :class:`Graph`.

    :class:`InputError` when the domain is not a Blocksworld the roles read (naming
    the action or predicate), when the problem has objects that are not blocks, or
    when the initial state is not a physical arrangement.
    """
    view = blocksworld_view(problem)
    blocks = list(view.blocks)
    others = sorted(set(problem.objects) - set(blocks))
    if others:
        raise InputError(
            f"{problem.problem_path}: the learned planner reads blocks only; "
            f"{', '.join(others)} {'is not a block' if len(others) == 1 else 'are not blocks'} "
            f"(block types: {', '.join(view.roles.block_types)})"
        )
    index = {b: i for i, b in enumerate(blocks)}
    return blocks, graph_of(view.init, view.goal, index, problem.problem_path)


def graph_of(init, goal, index: dict[str, int], where: str = "<state>") -> Graph:
    """A :class:`Graph` from canonical facts (``on``, ``on-table``, ``holding``, ...)."""
    n = len(index)
    below = [None] * n
    goal_below = [NO_GOAL] * n
    goal_clear, goal_held = [False] * n, [False] * n
    goal_arm_empty = False
    for f in init:
        if f[0] == "on":
            below[index[f[1]]] = index[f[2]]
        elif f[0] == "on-table":
            below[index[f[1]]] = TABLE
        elif f[0] == "holding":
            below[index[f[1]]] = HELD
    missing = [b for b, i in index.items() if below[i] is None]
    if missing or list(below).count(HELD) > 1:
        raise InputError(
            f"{where}: the initial state is not an arrangement of blocks the learned planner "
            f"can read ({', '.join(missing) + ' rest on nothing' if missing else 'two held'})"
        )
    for f in goal:
        if f[0] == "on":
            goal_below[index[f[1]]] = index[f[2]]
        elif f[0] == "on-table":
            goal_below[index[f[1]]] = TABLE
        elif f[0] == "clear":
            goal_clear[index[f[1]]] = True
        elif f[0] == "holding":
            goal_held[index[f[1]]] = True
        elif f[0] == "arm-empty":
            goal_arm_empty = True
    return Graph(
        tuple(below), tuple(goal_below), tuple(goal_clear), tuple(goal_held), goal_arm_empty
    )


class DomainActions:
    """The domain's own ground action for each of :func:`applicable`'s canonical actions.

    Called with one ``(head, block, other block or -1)``, it gives the first schema's
    action (in the domain's order) with that meaning whose parameter types fit and whose
    static preconditions (predicates no action changes, such as the renamed variant's
    ``(cube ?c)``) hold in ``:init``; None when no schema's do: an action the problem
    never allows, which the rollout never offers the network. ``restricted`` is False
    when every action is allowed (no static precondition, one block type): then nothing
    needs checking.
    """

    def __init__(self, problem: Problem, blocks: list[str]):
        self.problem, self.blocks = problem, blocks
        roles = blocksworld_roles(problem.domain)
        statics = problem.domain.static_predicates
        self._schemas = []
        for name, role in roles.actions.items():
            schema = problem.domain.actions[name]
            self._schemas.append((role, schema, [f for f in schema.pre if f[0] in statics]))
        self.restricted = len(roles.block_types) > 1 or any(s for _, _, s in self._schemas)
        self._memo: dict[tuple[str, int, int], GroundAction | None] = {}

    def __call__(self, action: tuple[str, int, int]) -> GroundAction | None:
        if action in self._memo:
            return self._memo[action]
        head, x, y = action
        kind = PICK if head in ("pick-up", "unstack") else PLACE
        found = None
        for role, schema, static in self._schemas:
            if role.kind != kind or (role.support is None) != (y < 0):
                continue
            args = [""] * schema.arity
            args[role.block] = self.blocks[x]
            if role.support is not None:
                args[role.support] = self.blocks[y]
            ground = GroundAction(schema.name, tuple(args))
            if check_action(self.problem, ground) is not None:
                continue
            binding = {var: arg for (var, _), arg in zip(schema.params, args, strict=True)}
            if all(tuple(binding.get(t, t) for t in f) in self.problem.init for f in static):
                found = ground
                break
        self._memo[action] = found
        return found

    def allows(self, action: tuple[str, int, int]) -> bool:
        """True when the problem has a ground action for ``action`` (see the class)."""
        return self(action) is not None


def unreachable_goal(problem: Problem) -> NoPlanError | None:
    """The classical planners' proof that no plan exists, where the domain restricts its
    actions: goal facts unreachable even with delete effects ignored (a block that no
    action may pick up, whose place the goal changes). None when none is found."""
    reached, _ = relaxed_reachable(problem.init, ground_all(problem))
    if problem.goal <= reached:
        return None
    found = "; ".join(diagnose(problem))
    return NoPlanError(
        f"no plan exists for problem '{problem.name}': proved before search, by the delete "
        f"relaxation; diagnosis: {found}"
    )


@dataclass(frozen=True)
class Rollout:
    """A learned planner's answer: the actions (by block index) and the states visited."""

    actions: tuple[tuple[str, int, int], ...]
    reason: str  # "goal", "loop", "budget", "time", "stuck"


def roll_out(
    learned: LearnedPlanner,
    graph: Graph,
    deadline: float | None = None,
    budget: int | None = None,
    allowed: Callable[[tuple[str, int, int]], bool] | None = None,
) -> Rollout:
    """Greedy rollout of the network's choices from ``graph``'s state until its goal holds.

    Only the :func:`applicable` actions that ``allowed`` accepts (all when None) are
    scored: the problem's static preconditions (:class:`DomainActions`).
    """
    n = len(graph.below)
    budget = 4 * n + 2 if budget is None else budget
    state, seen, taken = graph.below, {graph.below}, []
    while not satisfied(state, graph):
        if len(taken) >= budget:
            return Rollout(tuple(taken), "budget")
        if deadline is not None and time.perf_counter() > deadline:
            return Rollout(tuple(taken), "time")
        actions = applicable(state)
        if allowed is not None:
            actions = [a for a in actions if allowed(a)]
        if not actions:
            return Rollout(tuple(taken), "stuck")
        here = Graph(
            state, graph.goal_below, graph.goal_clear, graph.goal_held, graph.goal_arm_empty
        )
        best = actions[int(np.argmax(scores(learned.weights, here, actions)))]
        state = apply(state, best)
        taken.append(best)
        if state in seen:
            return Rollout(tuple(taken), "loop")
        seen.add(state)
    return Rollout(tuple(taken), "goal")


def plan_learned(
    problem: Problem, spec: str = "learned", time_limit: float | None = None
) -> tuple[tuple[GroundAction, ...], LearnedPlanner]:
    """The learned planner's plan for ``problem`` in its domain's own action names.

    :class:`NoPlanError` (the planners' exit 1) names why a rollout ended without
    reaching the goal: a loop, the step budget or the time limit. Where the domain
    restricts its actions (static preconditions such as ``(cube ?c)``), the network is
    offered only the actions the problem allows, and a goal those never reach is the
    classical planners' "no plan exists", with the same proof and diagnosis.
    """
    t0 = time.perf_counter()
    learned = load_planner(checkpoint_of(spec))
    blocks, graph = read_problem(problem)
    ground = DomainActions(problem, blocks)
    if ground.restricted:
        proof = unreachable_goal(problem)
        if proof is not None:
            raise proof
    deadline = None if time_limit is None else t0 + time_limit
    # The network's products are small (tens of rows): BLAS threads only compete with
    # each other and with the rest of the machine (a 50-block plan: 0.11 s on one thread,
    # 0.15 s on two cores, seconds beside other work).
    with threadpool_limits(limits=1, user_api="blas"):
        out = roll_out(
            learned, graph, deadline, allowed=ground.allows if ground.restricted else None
        )
    if out.reason != "goal":
        n = len(blocks)
        why = {
            "loop": f"its choice at step {len(out.actions)} returns to a state already visited "
            "(a loop)",
            "budget": f"it used its step budget ({4 * n + 2} actions for {n} blocks)",
            "time": f"it reached the {time_limit:g} s time limit" if time_limit else "time",
            "stuck": "no action is applicable",
        }[out.reason]
        raise NoPlanError(
            f"no plan found for problem '{problem.name}': the learned planner ({learned.path}) "
            f"gave up: {why}; this does not prove that no plan exists (try --planner auto)"
        )
    return tuple(ground(a) for a in out.actions), learned


def describe_folder(path: str | Path) -> str:
    """:func:`describe` of the checked checkpoint at ``path`` (:mod:`cake_drake.artifacts`)."""
    return describe(load_planner(path))


def describe(learned: LearnedPlanner) -> str:
    """One phrase for ``plan.txt`` and the layers line: the network, its training, its folder
    (``package://cake_drake/...`` for a shipped one, else the absolute path)."""
    t = learned.config.get("training")
    sizes = t.get("blocks") if isinstance(t, dict) else None
    trained = ""
    if isinstance(sizes, list) and len(sizes) == 2:
        how = " from the reward" if isinstance(t, dict) and "reward" in t else ""
        trained = f", trained{how} on {sizes[0]}-{sizes[1]} blocks"
    where = portable_path(learned.path)
    return f"relational network, width {learned.width}{trained}: {where}"
