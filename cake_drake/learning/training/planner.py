"""Training the learned planner (:mod:`cake_drake.symbolic.learned`) from exact labels.

Small Blocksworlds are solved exactly: every arrangement of n blocks (7,057 at
six blocks, the hand's states included) is enumerated once per size, and for
each sampled goal a breadth-first search from the goal's states gives every
state's true distance (Blocksworld's actions all have inverses, so the graph
is undirected). A state's **labels** are all its optimal actions: those whose
successor is one step closer. The network is trained to put its probability
mass on that set (the log of the summed softmax over the optimal actions), so
it never has to pick one optimal action over another it cannot tell apart.

States are drawn half uniformly from the whole space (what the monitor's
replanning from a disturbed world may hand it) and half along optimal paths
from random starts (what its own rollouts visit). Each batch runs the shared
layer a few more times than its problems need (0 to 3 extra passes), so the
layer learns a fixed point and can run as long as a 50-block tower needs.

The torch model's parameters have the numpy names and shapes of
:func:`cake_drake.symbolic.learned.weight_shapes`; :func:`export` writes them
with ``planner.json``, and :func:`cake_drake.symbolic.learned.load_planner`
reads them back for planning, without torch.
"""

from __future__ import annotations

import json
import random
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cake_drake.errors import InputError
from cake_drake.symbolic.learned import (
    BINARY_HEADS,
    FORMAT,
    GLOBAL_FEATURES,
    HELD,
    KIND,
    NO_GOAL,
    NODE_FEATURES,
    PAIR_FEATURES,
    RELATIONS,
    TABLE,
    UNARY_HEADS,
    Graph,
    applicable,
    apply,
    features,
    pair_features,
    rounds,
    satisfied,
    weight_shapes,
)

#: The largest problems the exact labels enumerate (every state of every size).
MAX_BLOCKS = 7


@dataclass(frozen=True)
class PlannerRecipe:
    """How the shipped planner was trained; every field a flag of ``train --planner``."""

    min_blocks: int = 3
    max_blocks: int = 6
    goals: int = 4000  # sampled goals, spread over the sizes
    states_per_goal: int = 24
    width: int = 64
    steps: int = 12000
    batch_size: int = 64
    lr: float = 2e-3
    extra_rounds: int = 3
    seed: int = 0


# --------------------------------------------------------------------------- exact labels


class Space:
    """Every arrangement of n blocks (arm empty or holding one) and its action edges."""

    def __init__(self, n: int):
        start = tuple([TABLE] * n)
        index = {start: 0}
        states = [start]
        edges: list[list[tuple[int, tuple[str, int, int]]]] = []
        queue = deque([start])
        while queue:
            s = queue.popleft()
            out = []
            for a in applicable(s):
                t = apply(s, a)
                if t not in index:
                    index[t] = len(states)
                    states.append(t)
                    queue.append(t)
                out.append((index[t], a))
            edges.append(out)
        self.n = n
        self.states = states
        self.index = index
        self.edges = edges
        self.array = np.array(states, dtype=np.int16)

    def distances(self, graph: Graph) -> np.ndarray:
        """Each state's number of actions to ``graph``'s goal (-1: unreachable)."""
        dist = np.full(len(self.states), -1, dtype=np.int32)
        queue = deque()
        for i, s in enumerate(self.states):
            if satisfied(s, graph):
                dist[i] = 0
                queue.append(i)
        while queue:  # the graph is undirected: every action has an inverse
            i = queue.popleft()
            for j, _ in self.edges[i]:
                if dist[j] < 0:
                    dist[j] = dist[i] + 1
                    queue.append(j)
        return dist


def _towers(n: int, rng: random.Random, tall: bool) -> list[list[int]]:
    order = list(range(n))
    rng.shuffle(order)
    out: list[list[int]] = []
    for b in order:
        if not out or rng.random() < (0.15 if tall else 0.5):
            out.append([b])
        else:
            rng.choice(out).append(b)
    return out


def random_goal(n: int, rng: random.Random) -> Graph:
    """A goal as the generators and IPC problems write them: complete towers, or a part of
    their ``on`` facts; now and then a ``clear`` or ``arm-empty`` fact too."""
    goal_below = [NO_GOAL] * n
    goal_clear = [False] * n
    towers = _towers(n, rng, tall=rng.random() < 0.3)
    partial = rng.random() < 0.5
    for t in towers:
        for k, b in enumerate(t):
            if k == 0:
                goal_below[b] = NO_GOAL if partial else TABLE
            elif not partial or rng.random() < 0.5:
                goal_below[b] = t[k - 1]
        if rng.random() < 0.1:
            goal_clear[t[-1]] = True
    if all(g == NO_GOAL for g in goal_below) and not any(goal_clear):
        t = max(towers, key=len)
        if len(t) > 1:
            goal_below[t[1]] = t[0]
        else:
            goal_below[t[0]] = TABLE
    return Graph(tuple([TABLE] * n), tuple(goal_below), tuple(goal_clear), (False,) * n,
                 rng.random() < 0.2)  # fmt: skip


@dataclass
class Sample:
    graph: Graph
    actions: list[tuple[str, int, int]]
    optimal: np.ndarray  # bool, one per action


def samples(recipe: PlannerRecipe, log=print) -> list[Sample]:
    """Labelled states: for each sampled goal, states and all their optimal actions."""
    rng = random.Random(recipe.seed)
    sizes = list(range(recipe.min_blocks, recipe.max_blocks + 1))
    spaces = {}
    out: list[Sample] = []
    for k in range(recipe.goals):
        n = sizes[k % len(sizes)]
        if n not in spaces:
            t0 = time.perf_counter()
            spaces[n] = Space(n)
            log(f"  {n} blocks: {len(spaces[n].states)} states ({time.perf_counter() - t0:.1f} s)")
        space = spaces[n]
        goal = random_goal(n, rng)
        dist = space.distances(goal)
        far = np.flatnonzero(dist > 0)
        if far.size == 0:
            continue
        chosen = [int(i) for i in rng.sample(list(far), min(len(far), recipe.states_per_goal // 2))]
        # ... and states along optimal paths from random starts with the arm empty
        empty = [int(i) for i in far if HELD not in space.states[i]]
        while len(chosen) < recipe.states_per_goal and empty:
            i = rng.choice(empty)
            while dist[i] > 0 and len(chosen) < recipe.states_per_goal:
                chosen.append(i)
                nxt = [j for j, _ in space.edges[i] if dist[j] == dist[i] - 1]
                i = rng.choice(nxt)
        for i in chosen:
            acts = [a for _, a in space.edges[i]]
            best = np.array([dist[j] == dist[i] - 1 for j, _ in space.edges[i]])
            g = goal
            out.append(Sample(Graph(space.states[i], g.goal_below, g.goal_clear, g.goal_held,
                                    g.goal_arm_empty), acts, best))  # fmt: skip
    return out


# --------------------------------------------------------------------------- the torch twin


def _model(width: int, seed: int):
    import torch  # seconds, the lerobot extra: only while training (a plan is numpy)

    torch.manual_seed(seed)
    params = {}
    for name, shape in weight_shapes(width).items():
        if name == "norm_g":
            t = torch.ones(shape)
        elif len(shape) == 1:
            t = torch.zeros(shape)
        else:
            t = torch.randn(shape) * (2.0 / shape[0]) ** 0.5
        params[name] = torch.nn.Parameter(t)
    return torch.nn.ParameterDict(params)


def _batch(batch: list[Sample], extra: int):
    """Numpy arrays of a batch: nodes, relations, graphs and actions, flattened."""
    x0s, gs, rels, graph_of, acts, labels, groups = [], [], [[] for _ in RELATIONS], [], [], [], []
    pairs = []
    offset, n_rounds = 0, 0
    for k, s in enumerate(batch):
        x0, g, rel = features(s.graph)
        n = x0.shape[0]
        x0s.append(x0)
        gs.append(g)
        for r, (xs, ys) in enumerate(rel):
            rels[r].append((xs + offset, ys + offset))
        graph_of.append(np.full(n, k))
        binary = [(x, y) for _, x, y in s.actions if y >= 0]
        if binary:
            xs, ys = np.array(binary).T
            pairs.append(pair_features(s.graph, xs, ys))
        for (kind, x, y), good in zip(s.actions, s.optimal, strict=True):
            head = (UNARY_HEADS + BINARY_HEADS).index(kind)
            acts.append((head, x + offset, (y + offset) if y >= 0 else -1))
            labels.append(good)
            groups.append(k)
        n_rounds = max(n_rounds, rounds(s.graph))
        offset += n
    rel_arrays = [
        (np.concatenate([a for a, _ in r]) if r else np.zeros(0, int),
         np.concatenate([b for _, b in r]) if r else np.zeros(0, int))
        for r in rels
    ]  # fmt: skip
    return (
        np.concatenate(x0s),
        np.stack(gs),
        rel_arrays,
        np.concatenate(graph_of),
        np.array(acts),
        np.array(labels),
        np.array(groups),
        n_rounds + extra,
        np.concatenate(pairs) if pairs else np.zeros((0, len(PAIR_FEATURES))),
    )


def _forward(p, arrays, n_graphs: int):
    """The action scores of a batch; the same arithmetic as the numpy planner's."""
    import torch  # seconds, the lerobot extra: only while training (a plan is numpy)

    x0, g, rels, graph_of, acts, _, _, n_rounds, pairs = arrays
    x0 = torch.as_tensor(x0, dtype=torch.float32)
    g = torch.as_tensor(g, dtype=torch.float32)
    gid = torch.as_tensor(graph_of)
    rels = [(torch.as_tensor(a), torch.as_tensor(b)) for a, b in rels]

    h = torch.relu(x0 @ p["enc_w"] + p["enc_b"])
    for _ in range(n_rounds):
        parts = [h, x0]
        for xs, ys in rels:
            parts.append(torch.zeros_like(h).index_add_(0, xs, h[ys]))
            parts.append(torch.zeros_like(h).index_add_(0, ys, h[xs]))
        parts.append(g[gid])
        z = torch.cat(parts, 1)
        delta = torch.relu(z @ p["upd1_w"] + p["upd1_b"]) @ p["upd2_w"] + p["upd2_b"]
        h = torch.nn.functional.layer_norm(h + delta, (h.shape[1],), p["norm_g"], p["norm_b"])
    un = torch.relu(h @ p["un1_w"] + p["un1_b"]) @ p["un2_w"] + p["un2_b"]
    acts = torch.as_tensor(acts)
    head, x, y = acts[:, 0], acts[:, 1], acts[:, 2]
    unary = head < len(UNARY_HEADS)
    score = torch.empty(len(acts))
    score[unary] = un[x[unary], head[unary]]
    b = ~unary
    pf = torch.as_tensor(pairs, dtype=torch.float32)
    pair = torch.relu(h[x[b]] @ p["bi_x"] + h[y[b]] @ p["bi_y"] + pf @ p["bi_p"] + p["bi1_b"])
    score[b] = (pair @ p["bi2_w"] + p["bi2_b"]).gather(1, (head[b] - 2).unsqueeze(1)).squeeze(1)
    return score


def _loss(score, labels, groups, n_graphs: int):
    """-log of the probability the softmax over each state's actions puts on its optimal ones."""
    import torch  # seconds, the lerobot extra: only while training (a plan is numpy)

    groups = torch.as_tensor(groups)
    labels = torch.as_tensor(labels)
    top = torch.full((n_graphs,), -1e9).scatter_reduce(0, groups, score.detach(), "amax")
    e = torch.exp(score - top[groups])
    total = torch.zeros(n_graphs).index_add_(0, groups, e)
    good = torch.zeros(n_graphs).index_add_(0, groups, e * labels)
    loss = (torch.log(total) - torch.log(good.clamp(min=1e-30))).mean()
    picked = torch.full((n_graphs,), -1e9).scatter_reduce(0, groups, score, "amax")
    right = torch.zeros(n_graphs).index_add_(
        0, groups, ((score >= picked[groups]) & labels).float()
    )
    return loss, (right > 0).float().mean().item()


def check_recipe(recipe: PlannerRecipe) -> None:
    """:class:`InputError` for a recipe that cannot train (said as the flag that set it)."""
    if (
        recipe.min_blocks < 2
        or recipe.max_blocks > MAX_BLOCKS
        or recipe.min_blocks > recipe.max_blocks
    ):
        raise InputError(
            f"--blocks {recipe.min_blocks} {recipe.max_blocks}: the exact labels enumerate "
            f"every state, so the sizes are 2 to {MAX_BLOCKS} blocks, the smaller first"
        )
    if recipe.steps < 1:
        raise InputError(f"--steps {recipe.steps}: a training takes at least one step")
    if recipe.batch_size < 1:
        raise InputError(f"--batch-size {recipe.batch_size}: at least 1")


def train_planner(recipe: PlannerRecipe, out, log=print) -> dict:
    """Train on exact labels of small problems and write the checkpoint (see :func:`export`
    for ``out``); returns what ``planner.json`` says of the training."""
    import torch  # seconds, the lerobot extra: only while training (a plan is numpy)

    check_recipe(recipe)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    log(f"labelling {recipe.goals} goals of {recipe.min_blocks}-{recipe.max_blocks} blocks")
    data = samples(recipe, log)
    t_data = time.perf_counter() - t0
    log(f"{len(data)} labelled states in {t_data:.0f} s")
    p = _model(recipe.width, recipe.seed)
    opt = torch.optim.Adam(p.parameters(), lr=recipe.lr)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, recipe.steps)
    rng = random.Random(recipe.seed + 1)
    t1, acc_window = time.perf_counter(), []
    for step in range(1, recipe.steps + 1):
        batch = rng.sample(data, min(recipe.batch_size, len(data)))
        arrays = _batch(batch, rng.randint(0, recipe.extra_rounds))
        score = _forward(p, arrays, len(batch))
        loss, acc = _loss(score, arrays[5], arrays[6], len(batch))
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        acc_window.append(acc)
        if step % 250 == 0 or step == recipe.steps:
            log(f"step {step}/{recipe.steps}: loss {loss.item():.4f}, greedy choice optimal "
                f"{np.mean(acc_window):.3f} ({(time.perf_counter() - t1) / step * 1000:.0f} ms "
                "a step)")  # fmt: skip
            acc_window = []
    weights = {k: v.detach().numpy().astype(np.float32) for k, v in p.items()}
    info = {
        "blocks": [recipe.min_blocks, recipe.max_blocks],
        "labels": "every optimal action (breadth-first search over all states)",
        "goals": recipe.goals,
        "states": len(data),
        "steps": recipe.steps,
        "batch_size": recipe.batch_size,
        "lr": recipe.lr,
        "extra_rounds": recipe.extra_rounds,
        "seed": recipe.seed,
        "minutes": round((time.perf_counter() - t0) / 60, 2),
    }
    export(weights, recipe.width, info, out)
    return info


#: The files of a learned planner's checkpoint folder.
FILES = ("planner.json", "weights.npz")


def export(weights: dict[str, np.ndarray], width: int, training: dict, out) -> None:
    """Write ``planner.json`` and ``weights.npz``: into ``out``'s staging when it is an
    :class:`~cake_drake.outputs.files.OutputDir` (whole or not at all), else into the
    folder ``out`` (created)."""
    if isinstance(out, str | Path):
        Path(out).mkdir(parents=True, exist_ok=True)
        path_of = Path(out).__truediv__
    else:
        path_of = out.path
    cfg = {
        "kind": KIND,
        "format": FORMAT,
        "architecture": {
            "width": width,
            "node_features": list(NODE_FEATURES),
            "global_features": list(GLOBAL_FEATURES),
            "relations": list(RELATIONS),
            "pair_features": list(PAIR_FEATURES),
            "rounds": "the tallest tower (current or goal) + 2",
        },
        "training": training,
    }
    with open(path_of("weights.npz"), "wb") as f:
        np.savez(f, **weights)
    path_of("planner.json").write_text(json.dumps(cfg, indent=2) + "\n", encoding="utf-8")
