"""Training the learned planner from the goal's reward alone (``train --planner --reward``).

The same network as :mod:`.planner`'s (:func:`cake_drake.symbolic.learned.weight_shapes`),
the same checkpoint files, but no labels: no search tells it which action is good.
Each update draws problems (a random start, a random goal as the generators write them:
complete towers or a part of their ``on`` facts), lets the network's own softmax play
each problem several times in the symbolic model, and scores every episode by the
reward alone: 1 when the goal holds, less a small price per action; the step budget
(4 actions a block, the planner's own) ends an episode that never gets there.

The gradient is REINFORCE with a leave-one-out baseline (each episode against the mean
of the others on the same problem, so "shorter than its siblings" is what is rewarded
once every sibling solves it) and a small entropy bonus. A curriculum starts at 2 blocks
and adds one whenever the episodes at the largest size solve their problems often
enough, up to ``max_blocks``; smaller sizes keep being drawn so nothing is forgotten.

Episodes are played in batches: one forward pass of the torch model scores every
unfinished episode's actions a step, and the whole batch's visited states go through
one more pass, with gradients, for the update.
"""

from __future__ import annotations

import random
import time
from dataclasses import dataclass

import numpy as np

from cake_drake.errors import InputError
from cake_drake.learning.training.planner import (
    Sample,
    _batch,
    _forward,
    _model,
    _towers,
    export,
    random_goal,
)
from cake_drake.symbolic.learned import HELD, TABLE, Graph, applicable, apply, satisfied

#: The greedy checks' problems come from seeds no training draws.
CHECK_SEED = 10_000_000


@dataclass(frozen=True)
class RewardRecipe:
    """How ``models/planners/blocks_reward`` was trained; every field a flag or default of
    ``train --planner --reward``."""

    min_blocks: int = 2
    max_blocks: int = 12
    steps: int = 700  # updates
    problems: int = 16  # problems an update
    rollouts: int = 8  # episodes a problem (the leave-one-out baseline's group)
    width: int = 64
    lr: float = 3e-4
    step_price: float = 0.1  # the reward lost per action, times the block count
    entropy: float = 0.01
    promote: float = 0.9  # success at the largest size that adds a block
    extra_rounds: int = 2
    check_every: int = 50  # updates between greedy checks (the best check's weights kept)
    check_sizes: tuple[int, ...] = (20, 50)
    check_problems: int = 16
    seed: int = 0


def check_recipe(recipe: RewardRecipe) -> None:
    """:class:`InputError` for a recipe that cannot train (said as the flag that set it)."""
    if recipe.min_blocks < 2 or recipe.min_blocks > recipe.max_blocks:
        raise InputError(
            f"--blocks {recipe.min_blocks} {recipe.max_blocks}: the curriculum starts at 2 "
            "blocks or more and ends at its largest size, the smaller first"
        )
    if recipe.max_blocks > 20:
        raise InputError(
            f"--blocks {recipe.min_blocks} {recipe.max_blocks}: at most 20 blocks in "
            "training (the network reads any size; episodes grow with the square of it)"
        )
    if recipe.steps < 1:
        raise InputError(f"--steps {recipe.steps}: a training takes at least one step")
    if recipe.problems < 1:
        raise InputError(f"--batch-size {recipe.problems}: at least 1 problem an update")


def random_problem_graph(n: int, rng: random.Random) -> Graph:
    """A start and a goal of ``n`` blocks that are not the same: random towers (now and then
    a block in the hand) and :func:`~.planner.random_goal`'s goal."""
    while True:
        below = [TABLE] * n
        for tower in _towers(n, rng, tall=rng.random() < 0.3):
            for k in range(1, len(tower)):
                below[tower[k]] = tower[k - 1]
        if rng.random() < 0.1:
            covered = {j for j in below if j >= 0}
            clear = [i for i in range(n) if i not in covered]
            below[rng.choice(clear)] = HELD
        g = random_goal(n, rng)
        graph = Graph(tuple(below), g.goal_below, g.goal_clear, g.goal_held, g.goal_arm_empty)
        if not satisfied(graph.below, graph):
            return graph


def _at(graph: Graph, below: tuple[int, ...]) -> Graph:
    return Graph(below, graph.goal_below, graph.goal_clear, graph.goal_held, graph.goal_arm_empty)


@dataclass
class Episode:
    graph: Graph  # the problem (start and goal)
    problem: int  # index of the problem in the update (the baseline's group)
    state: tuple[int, ...]
    steps: list[Sample]  # each visited state, its actions, the chosen one marked
    solved: bool = False

    @property
    def done(self) -> bool:
        return self.solved or len(self.steps) >= 4 * len(self.state)


def play(p, episodes: list[Episode], rng: np.random.Generator, greedy: bool = False) -> None:
    """Play every episode to its end: each step, one batched forward pass scores all the
    unfinished episodes' actions, and each takes a sample of its softmax (or its best)."""
    import torch  # the lerobot extra: only while training (a plan is numpy)

    while True:
        live = [e for e in episodes if not e.done]
        if not live:
            return
        batch = []
        for e in live:
            acts = applicable(e.state)
            batch.append(Sample(_at(e.graph, e.state), acts, np.zeros(len(acts), bool)))
        arrays = _batch(batch, 0)
        with torch.no_grad():
            score = _forward(p, arrays, len(batch)).numpy()
        groups = arrays[6]
        start = 0
        for e, s in zip(live, batch, strict=True):
            k = len(s.actions)
            z = score[start : start + k]
            start += k
            if greedy:
                pick = int(np.argmax(z))
            else:
                prob = np.exp(z - z.max())
                pick = int(rng.choice(k, p=prob / prob.sum()))
            s.optimal[pick] = True
            e.steps.append(s)
            e.state = apply(e.state, s.actions[pick])
            e.solved = satisfied(e.state, e.graph)
        assert start == len(groups)


def returns(episodes: list[Episode], price: float) -> np.ndarray:
    """Each episode's reward: 1 for a solved goal, less ``price`` / n a step."""
    return np.array(
        [float(e.solved) - price * len(e.steps) / len(e.state) for e in episodes], np.float64
    )


def advantages(r: np.ndarray, problem: np.ndarray) -> np.ndarray:
    """Leave-one-out: each episode's return less the mean of its problem's other episodes."""
    out = np.zeros_like(r)
    for k in np.unique(problem):
        m = problem == k
        n = int(m.sum())
        if n > 1:
            out[m] = r[m] - (r[m].sum() - r[m]) / (n - 1)
    return out


def _log_probs(score, groups: np.ndarray, chosen: np.ndarray, n_states: int):
    """(log-probability of each state's chosen action, each state's entropy) under the
    softmax over that state's actions."""
    import torch  # the lerobot extra: only while training (a plan is numpy)

    g = torch.as_tensor(groups)
    top = torch.full((n_states,), -1e9).scatter_reduce(0, g, score.detach(), "amax")
    z = score - top[g]
    log_total = torch.log(torch.zeros(n_states).index_add(0, g, torch.exp(z)))
    logp = z - log_total[g]
    picked = torch.zeros(n_states).index_add(0, g, logp * torch.as_tensor(chosen, dtype=z.dtype))
    entropy = -torch.zeros(n_states).index_add(0, g, torch.exp(logp) * logp)
    return picked, entropy


def evaluate(p, sizes: tuple[int, ...], count: int, seed: int) -> dict[int, tuple[float, float]]:
    """Greedy play of ``count`` problems a size: (share solved, mean actions a block)."""
    out = {}
    for n in sizes:
        rng = random.Random(seed + n)
        eps = [Episode(g, i, g.below, []) for i, g in
               enumerate(random_problem_graph(n, rng) for _ in range(count))]  # fmt: skip
        play(p, eps, np.random.default_rng(0), greedy=True)
        out[n] = (np.mean([e.solved for e in eps]), np.mean([len(e.steps) / n for e in eps]))
    return out


def train_planner_reward(recipe: RewardRecipe, out, log=print) -> dict:
    """Train from the reward alone and write the checkpoint (:func:`.planner.export`);
    returns what ``planner.json`` says of the training."""
    import torch  # the lerobot extra: only while training (a plan is numpy)

    check_recipe(recipe)
    torch.set_num_threads(1)
    t0 = time.perf_counter()
    p = _model(recipe.width, recipe.seed)
    opt = torch.optim.Adam(p.parameters(), lr=recipe.lr)
    rng = random.Random(recipe.seed)
    nrng = np.random.default_rng(recipe.seed)
    level, states_seen, episodes_played = recipe.min_blocks, 0, 0
    window: list[float] = []
    curriculum = [(0, level)]
    best, best_key, checks = None, None, []
    for step in range(1, recipe.steps + 1):
        # half the problems at the curriculum's largest size, half below it
        sizes = [
            level
            if k % 2 == 0 or level == recipe.min_blocks
            else rng.randint(recipe.min_blocks, level)
            for k in range(recipe.problems)
        ]
        episodes = []
        for k, n in enumerate(sizes):
            g = random_problem_graph(n, rng)
            episodes += [Episode(g, k, g.below, []) for _ in range(recipe.rollouts)]
        play(p, episodes, nrng)
        r = returns(episodes, recipe.step_price)
        problem = np.array([e.problem for e in episodes])
        adv = advantages(r, problem)
        scale = adv.std() + 1e-6
        samples = [s for e in episodes for s in e.steps]
        weight = np.concatenate(
            [np.full(len(e.steps), a / scale) for e, a in zip(episodes, adv, strict=True)]
        )
        arrays = _batch(samples, rng.randint(0, recipe.extra_rounds))
        score = _forward(p, arrays, len(samples))
        logp, ent = _log_probs(score, arrays[6], arrays[5], len(samples))
        w = torch.as_tensor(weight, dtype=logp.dtype)
        loss = -(w * logp).sum() / len(episodes) - recipe.entropy * ent.mean()
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(p.parameters(), 1.0)
        opt.step()
        states_seen += len(samples)
        episodes_played += len(episodes)
        top = [e.solved for e in episodes if len(e.state) == level]
        window = (window + top)[-recipe.problems * recipe.rollouts * 4 :]
        if (
            level < recipe.max_blocks
            and len(window) >= recipe.problems * recipe.rollouts * 2
            and np.mean(window) >= recipe.promote
        ):
            level += 1
            window = []
            curriculum.append((step, level))
            log(f"step {step}: the curriculum moves to {level} blocks")
        if step % 25 == 0 or step == recipe.steps:
            solved = np.mean([e.solved for e in episodes])
            per = np.mean([len(e.steps) / len(e.state) for e in episodes if e.solved] or [0])
            log(f"step {step}/{recipe.steps}: {level} blocks, sampled episodes solved "
                f"{solved:.2f}, {per:.2f} actions a block when solved, {states_seen} states "
                f"({(time.perf_counter() - t0) / step:.2f} s a step)")  # fmt: skip
        if level == recipe.max_blocks and (step % recipe.check_every == 0 or step == recipe.steps):
            # greedy play, as the planner plans, on problems larger than any trained on
            found = evaluate(p, recipe.check_sizes, recipe.check_problems, CHECK_SEED)
            key = (sum(s for s, _ in found.values()), -sum(a for _, a in found.values()))
            checks.append([step] + [[n, round(s, 3), round(a, 3)] for n, (s, a) in found.items()])
            log(f"step {step}: greedy check " + ", ".join(
                f"{n} blocks {s:.0%} solved, {a:.2f} actions a block" for n, (s, a) in found.items()
            ))  # fmt: skip
            if best_key is None or key > best_key:
                best_key, best = key, {k: v.detach().clone() for k, v in p.items()}
                best_step = step
    kept = best if best is not None else {k: v.detach() for k, v in p.items()}
    weights = {k: v.numpy().astype(np.float32) for k, v in kept.items()}
    info = {
        "blocks": [recipe.min_blocks, recipe.max_blocks],
        "labels": "none: the goal's reward alone (REINFORCE, leave-one-out baseline, "
        "a curriculum over the number of blocks)",
        "reward": f"1 when the goal holds, less {recipe.step_price} x actions / blocks",
        "steps": recipe.steps,
        "problems_per_step": recipe.problems,
        "rollouts_per_problem": recipe.rollouts,
        "episodes": episodes_played,
        "states": states_seen,
        "curriculum": [[s, n] for s, n in curriculum],
        "checks": checks,
        "kept": f"the weights of step {best_step}" if best is not None else "the last weights",
        "lr": recipe.lr,
        "entropy": recipe.entropy,
        "extra_rounds": recipe.extra_rounds,
        "seed": recipe.seed,
        "minutes": round((time.perf_counter() - t0) / 60, 2),
    }
    export(weights, recipe.width, info, out)
    return info
