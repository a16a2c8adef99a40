"""``train``: a policy, DAgger, a residual, the learned planner or RL, trained.

Six modes, each chosen by a flag (a policy on a recording by none) and each declared
with the flags it reads (:data:`MODES`): a flag given that the chosen mode does not read
is refused in one line naming the flag and the mode (:func:`refuse_unread`), before any
work. The training is the library's (:mod:`cake_drake.learning`).
"""

from __future__ import annotations

import argparse
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from cake_drake.commands.common import (
    CliParser,
    add_ray_flag,
    add_set_flag,
    ray_engine,
    worker_count,
)
from cake_drake.errors import EXIT_OK, InputError

TRAIN_DOC = """Train a policy on a recording with LeRobot's own training loop, offline.

DATASET is a folder written by python -m cake_drake.record. With no other flag the
recipe of the recording's task is used (models/scenarios/learning.yaml: policy, inputs,
steps, batch size, network size); flags override it. --policy mlp is the project's own
policy (a multilayer perceptron predicting joint offsets in chunks, registered with
LeRobot as the policy type cake_mlp), act and diffusion are LeRobot's ACT and Diffusion
Policy, trained with the recipe's part for them where the recipe trains another policy
(its act: and diffusion: fields, e.g. a smaller learning rate). --inputs state reads the
joints and observation.environment_state (the cubes' poses and the goal); images the
joints and the cameras (mlp: a small encoder a camera, and the goal without the poses;
both train on a CPU, ACT's and Diffusion Policy's image encoders are GPU work); both all
of them (act, diffusion); skill a learned skill; relative a skill that never sees the
arm (observation.relative: the action from the hand and the gripper's width; it
answers hand moves and the gripper as a decision, trained on the CPU into
OUT/skill.json and OUT/weights.npz, on a recording of the hand's moves).
Nothing is downloaded: the dataset is read from its folder and backbones start from
scratch unless --weights names a file. The checkpoint is LeRobot's
(OUT/checkpoints/last/pretrained_model): evaluate it with python -m cake_drake.evaluate
OUT, or run it with reference: !Policy {checkpoint: OUT}. --resume continues OUT's
training up to --steps.

--dagger ROUNDS trains the recipe on DATASET, then each round rolls the checkpoint out for
--episodes-per-round N episodes (default %(per_round)d) of the recording's task
(report.json's spec), on seeds after the recording's, on the local pool (--workers) or
Ray (--ray), the expert's action executed instead with probability --beta B (default 0;
drawn from the episode's seed); the recording's demonstrator (the closed-loop expert)
labels every visited state, and an episode ends where it is done or the step budget runs
out. Each round writes a new LeRobot dataset, OUT/data/round-K (the recording's kept
episodes and every DAgger episode so far; a frame's actor is 0 where the expert acted, 1
where the learner did), and fine-tunes the last checkpoint on it for --round-steps steps
(default: the recipe's). The last round's checkpoint is OUT's, as any training's; each
training keeps its folder in OUT/rounds/round-K. Prints, per round, the episodes, the
frames added, the expert-labelled frames in all and the learner's success in the round's
rollouts. OUT changes only when the last round has finished (an error or Ctrl-C in any
round leaves it as it was). State policies and skills (--inputs state, skill, relative);
a skill that never sees the arm (relative) acts as the network alone, with no shield
step, is trained afresh each round on every frame so far, and OUT is the last round's
skill (OUT/skill.json and OUT/weights.npz: run it with motion.skills: OUT).

--residual fits the dynamic layer's learned residual instead: DATASET... are run folders
written with outputs.logs: true (their logs.npz); the residual, tau = tau_IDC + r(q, v,
q_d, v_d, a_d, gripper), is linear in features of the arm's kinematics and fitted by
least squares to tau_applied - tau_model at the measured state and acceleration, the last
fifth of each run held out. OUT gets residual.json; a scenario uses it with controller:
!ComputedTorque {residual: OUT}.

--planner trains the symbolic layer's learned planner instead, from no dataset: every
state of Blocksworlds of --blocks MIN MAX blocks (default %(min_blocks)d %(max_blocks)d,
at most %(most)d) is enumerated, each sampled goal's exact distances give every state's
optimal actions, and a relational network learns to put its choice on them (--steps,
default %(steps)d; --batch-size, default %(batch_size)d; --seed). OUT gets planner.json
and weights.npz: plan with it as --planner learned@OUT (python -m cake_drake.plan, run,
a scenario's task.planner). With --reward it learns from the goal's reward alone instead:
no search labels anything; the network plays random problems in the symbolic model
(REINFORCE, each episode against its problem's other episodes, a curriculum from 2 blocks
up to --blocks' MAX, default 12; --batch-size problems an update, default 16), and keeps the
weights that planned best in greedy checks on 20 and 50 blocks.

--perception trains the learned eyes instead: DATASET... are frames datasets (python -m
cake_drake.record --frames, with the same cameras): every cube the perception cameras saw
with its true pose. A point network (each point's offset from the cube's points' median
and its ray in, a weighed vote for the centre and the yaw out) learns them on the CPU
(--steps, default %(eyes_steps)d; --batch-size sightings, default %(eyes_batch)d;
--minutes, a wall-clock cap; --seed), the last tenth of the runs held out and the best
check's weights kept. OUT gets perception.json, weights.npz and progress.csv: run with
--perception learned@OUT.

--rl SUITE --name TASK learns TASK of the scenario file SUITE from a reward instead, from
no dataset: Stable-Baselines3's PPO (or SAC) on CakeDrake/Stack-v0 with the task's
episodes, with the task's training.rl recipe (algorithm, steps, environments side by side,
the reward's weights; models/scenarios/learning.yaml). With a base (the recipe's, or
--base DIR: a policy learned by imitation) the learner is a bounded residual on the
frozen base; without one it learns from scratch. --steps, --envs and --algorithm
override the recipe. With --ray the environments run as Ray actors, one CPU each (on a
local instance, or on the cluster at ADDRESS, started with `ray start`), the learner
here: the same recipe, reward and folder. Prints, every rollout, the environment steps,
steps/s, the episodes' return and success. OUT gets model.zip, rl.json, progress.csv and
curve.png; evaluate it with python -m cake_drake.evaluate OUT, or run it with reference:
!Policy {checkpoint: OUT}.

Exit codes: 0 trained; 2 bad input (a dataset lacking what the policy needs, a device
that is not here, --dagger below 1, --beta outside 0 to 1, --dagger on a dataset with no
task to roll a policy out on or no kept episodes, DAgger's flags without --dagger, an RL
budget of no steps or less than one rollout, a reward term that does not exist or a weight
that is no number, a base that is no policy of the task's action space); 4 the checkpoint
could not be written; 130 interrupted.
"""


#: The largest seed a training takes: NumPy's and PyTorch's generators take 32 bits, and
#: DAgger seeds round K with seed + K.
TRAIN_SEED_MAX = 2**31 - 1
#: DAgger's rollouts a round unless --episodes-per-round says otherwise.
EPISODES_PER_ROUND = 10


def train_parser() -> argparse.ArgumentParser:
    from dataclasses import asdict

    from cake_drake.learning.training.planner import MAX_BLOCKS, PlannerRecipe

    p = CliParser(
        prog="python -m cake_drake.train",
        description=TRAIN_DOC
        % {
            **asdict(PlannerRecipe()),
            "most": MAX_BLOCKS,
            "per_round": EPISODES_PER_ROUND,
            "eyes_steps": PERCEPTION_RECIPE["steps"],
            "eyes_batch": PERCEPTION_RECIPE["batch_size"],
        },
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "dataset", type=Path, nargs="*",
        help="a recording (python -m cake_drake.record); with --residual, run folders; "
        "none with --planner",
    )  # fmt: skip
    p.add_argument("--out", type=Path, required=True, help="the training's folder")
    p.add_argument(
        "--residual", action="store_true",
        help="fit the dynamic layer's residual to run folders written with outputs.logs",
    )  # fmt: skip
    p.add_argument(
        "--planner", action="store_true",
        help="train the symbolic layer's learned planner (exact labels, no dataset)",
    )  # fmt: skip
    p.add_argument(
        "--reward", action="store_true",
        help="--planner: from the goal's reward alone (policy gradient, a curriculum), no labels",
    )  # fmt: skip
    p.add_argument(
        "--blocks", type=int, nargs=2, metavar=("MIN", "MAX"),
        help=f"--planner: the problems' sizes (default {PlannerRecipe.min_blocks} "
        f"{PlannerRecipe.max_blocks})",
    )  # fmt: skip
    p.add_argument(
        "--perception", action="store_true",
        help="train the learned eyes on a frames dataset (python -m cake_drake.record --frames)",
    )  # fmt: skip
    p.add_argument(
        "--minutes", type=float,
        help="--perception: stop at this wall-clock budget (default: the steps alone)",
    )  # fmt: skip
    p.add_argument(
        "--rl",
        type=Path,
        metavar="SUITE",
        help="learn a task of this scenario file from a reward (with --name)",
    )
    p.add_argument("--name", help="--rl: the task (a scenario's name in SUITE)")
    p.add_argument("--base", help="--rl: a frozen policy's checkpoint the learner corrects")
    p.add_argument("--algorithm", help="--rl: ppo | sac (default: the recipe's)")
    p.add_argument("--envs", type=int, help="--rl: environments side by side (default: recipe's)")
    p.add_argument("--policy", help="mlp | act | diffusion (default: the recipe's)")
    p.add_argument(
        "--inputs", help="state | images | both | skill | relative (default: the recipe's)"
    )
    p.add_argument(
        "--cameras",
        nargs="+",
        metavar="NAME",
        help="the cameras an image policy reads (default: all the recording's)",
    )
    p.add_argument("--steps", type=int, help="training steps (default: the recipe's)")
    p.add_argument("--batch-size", type=int, help="batch size (default: the recipe's)")
    p.add_argument("--device", default="auto", help="auto | cpu | cuda (default auto)")
    p.add_argument(
        "--seed", type=int, default=0,
        help=f"the training's seed, 0 to {TRAIN_SEED_MAX} (default 0; DAgger's round K: +K)",
    )  # fmt: skip
    p.add_argument("--weights", help="a vision backbone's weights file (default: from scratch)")
    p.add_argument("--resume", action="store_true", help="continue OUT's last checkpoint")
    p.add_argument("--dagger", type=int, metavar="ROUNDS", help="rounds of DAgger after training")
    p.add_argument("--episodes-per-round", type=int, metavar="N", help="DAgger: rollouts a round")
    p.add_argument("--beta", type=float, metavar="B", help="DAgger: P(the expert's action runs)")
    p.add_argument("--round-steps", type=int, metavar="N", help="DAgger: fine-tuning steps")
    p.add_argument("--workers", type=int, help="DAgger: rollout processes (default: cores)")
    add_ray_flag(p)
    add_set_flag(p, "the --rl scenario")
    return p


def main_train(argv: list[str] | None = None) -> int:
    parser = train_parser()
    args = parser.parse_args(argv)
    if not 0 <= args.seed <= TRAIN_SEED_MAX:  # every mode seeds NumPy's and torch's generators
        raise InputError(f"--seed {args.seed}: a whole number from 0 to {TRAIN_SEED_MAX}")
    mode = chosen_mode(args, parser)
    refuse_unread(args, parser, mode)
    return mode.main(args)


@dataclass(frozen=True)
class Mode:
    """One way ``train`` trains: the flag that chooses it, the flags it reads, its main."""

    chooser: str | None  # the flag that chooses it (argparse's name); None: no flag does
    whose: str  # whose settings the flags only this mode reads are: "RL's"
    reads: frozenset[str]  # the flags it reads (argparse's names), its chooser among them
    refusal: str  # why a flag another mode reads is refused with this one
    main: Callable[[argparse.Namespace], int]

    @property
    def flag(self) -> str:
        return _flag(self.chooser) if self.chooser else "DATASET"


def _flag(name: str) -> str:
    """The flag of an argparse name: ``batch_size`` -> ``--batch-size``."""
    return "--" + name.replace("_", "-")


def _given(args: argparse.Namespace, parser: argparse.ArgumentParser, name: str) -> bool:
    return getattr(args, name) != parser.get_default(name)


def chosen_mode(args: argparse.Namespace, parser: argparse.ArgumentParser) -> Mode:
    """The first mode of :data:`MODES` whose flag is given (the last mode has none)."""
    return next(m for m in MODES if m.chooser is None or _given(args, parser, m.chooser))


def refuse_unread(args: argparse.Namespace, parser: argparse.ArgumentParser, mode: Mode) -> None:
    """Refuse, in one line, the first flag given (in the parser's order) that ``mode`` does
    not read: ``--X without --M: it is one of M's settings`` for a flag only mode M reads,
    ``--X with --MODE: ...`` (the mode's reason) for any other. What every mode reads
    (DATASET, whose use each mode checks with its own words, ``--out``, ``--traceback``) is
    never refused here."""
    for name in vars(args):  # argparse sets every name, in the parser's order
        if name in EVERY_MODE or name in mode.reads or not _given(args, parser, name):
            continue
        readers = [m for m in MODES if name in m.reads]
        if len(readers) == 1 and readers[0].chooser not in (None, name):
            owner = readers[0]
            raise InputError(
                f"{_flag(name)} without {owner.flag}: it is one of {owner.whose} settings"
            )
        raise InputError(f"{_flag(name)} with {mode.flag}: {mode.refusal}")


def _datasets(args: argparse.Namespace) -> list[Path]:
    """The DATASET arguments of a mode that reads them: at least one."""
    if not args.dataset:
        raise InputError("no DATASET given: train reads a recording (or run folders with "
                         "--residual, frames datasets with --perception; none with "
                         "--planner)")  # fmt: skip
    return args.dataset


def _main_policy(args: argparse.Namespace) -> int:
    """A policy trained on one recording by LeRobot's loop, then ``--dagger``'s rounds."""
    from dataclasses import replace

    from cake_drake.learning.training.train import for_inputs, for_policy, recipe_of, train

    if len(_datasets(args)) != 1:
        raise InputError(f"{len(args.dataset)} datasets given; train takes one recording "
                         "(several run folders go with --residual)")  # fmt: skip
    args.dataset = args.dataset[0]
    recipe, report = recipe_of(args.dataset)
    recipe = for_policy(for_inputs(recipe, args.inputs), args.policy)
    given = {
        "steps": args.steps,
        "batch_size": args.batch_size,
    }
    recipe = replace(recipe, **{k: v for k, v in given.items() if v is not None})
    if args.cameras:
        recipe = replace(recipe, images=replace(recipe.images, cameras=list(args.cameras)))
    if args.weights is not None and not Path(args.weights).is_file():
        raise InputError(f"--weights {args.weights}: no such file")
    if args.dagger is not None:
        return _main_dagger(args, recipe)
    if recipe.inputs == "relative":
        return _main_relative(args, recipe)
    folder = train(
        args.dataset, args.out, recipe, args.device, args.seed, args.resume, args.weights
    )
    print(
        f"{args.out}: {recipe.policy} ({recipe.inputs}) trained {recipe.steps} steps on "
        f"{args.dataset}; checkpoint {folder}"
    )
    return EXIT_OK


def check_relative(args: argparse.Namespace, recipe) -> None:
    """What a relative skill's training cannot take, refused in one line (exit 2)."""
    unread = [f for f in ("resume", "weights", "cameras") if getattr(args, f)]
    if recipe.policy != "mlp" or unread:
        what = f"--{unread[0]}" if unread else f"--policy {recipe.policy}"
        if not unread and args.policy is None:  # the recipe's: none in report.json says mlp
            what = (f"policy {recipe.policy} (the recipe of {Path(args.dataset) / 'report.json'}"
                    ", or the default where it has none)")  # fmt: skip
        raise InputError(f"{what} with --inputs relative: a relative skill is a perceptron "
                         "trained on the CPU from its recording alone (--policy mlp)")  # fmt: skip
    if args.device not in ("auto", "cpu"):
        raise InputError(f"--device {args.device} with --inputs relative: it trains on the CPU")


def _main_relative(args: argparse.Namespace, recipe) -> int:
    """A skill that never sees the arm, trained on the recording of the hand's moves."""
    from cake_drake.learning.skills.train_relative import FILES, train_recipe
    from cake_drake.outputs.files import OutputDir

    check_relative(args, recipe)
    with OutputDir(args.out, "train", FILES, [args.dataset]) as staged:
        info = train_recipe(Path(args.dataset), staged.staging, recipe, args.seed,
                            progress=lambda line: print(line, flush=True))  # fmt: skip
        staged.commit()
    print(
        f"{args.out}: relative skill trained {recipe.steps} steps on {info['frames']} frames "
        f"of {args.dataset} in {info['minutes']:.1f} min (gripper decided right on "
        f"{100 * info['gripper_accuracy']:.1f} % of them); run it with motion.skills: {args.out}"
    )
    return EXIT_OK


#: The learned eyes' recipe: steps, batch (sightings), learning rate, network width.
PERCEPTION_RECIPE = {"steps": 24000, "batch_size": 32, "lr": 2e-3, "width": 128}


def _main_perception(args: argparse.Namespace) -> int:
    """The learned eyes, trained on one frames dataset on the CPU."""
    from cake_drake.learning.data.frames import read_frames
    from cake_drake.learning.training.perception import FILES, train_perception
    from cake_drake.outputs.files import OutputDir

    frames = _datasets(args)
    for folder in frames:  # refused in one line before any folder is made
        read_frames(folder)
    if args.device not in ("auto", "cpu"):
        raise InputError(f"--device {args.device} with --perception: it trains on the CPU")
    steps = args.steps if args.steps is not None else PERCEPTION_RECIPE["steps"]
    batch = args.batch_size if args.batch_size is not None else PERCEPTION_RECIPE["batch_size"]
    if not 1 <= steps <= 10_000_000 or not 1 <= batch <= 4096:
        raise InputError(f"--steps {steps}, --batch-size {batch}: steps 1 to 10000000, "
                         "a batch of 1 to 4096 sightings")  # fmt: skip
    if args.minutes is not None and not 0 < args.minutes <= 10_000:
        raise InputError(f"--minutes {args.minutes}: more than 0, at most 10000")
    with OutputDir(args.out, "train", FILES, frames) as staged:
        info = train_perception(
            frames, staged, steps, batch, PERCEPTION_RECIPE["lr"], PERCEPTION_RECIPE["width"],
            args.seed, args.minutes, progress=lambda line: print(line, flush=True),
        )  # fmt: skip
        staged.commit()
    kept = info["kept"]
    print(f"{args.out}: learned eyes trained {info['steps']} steps on {info['samples']} "
          f"sightings in {info['minutes']:.1f} min; held out ({info['held_out']}): "
          f"{kept['median_mm']:.2f} / {kept['p95_mm']:.2f} mm, yaw p95 "
          f"{kept['yaw_p95_deg']:.2f} deg; run it with --perception "
          f"learned@{args.out}")  # fmt: skip
    return EXIT_OK


def _main_residual(args: argparse.Namespace) -> int:
    from cake_drake.learning.training.residual import describe, train_residual

    train_residual(_datasets(args), args.out)
    print(describe(args.out))
    return EXIT_OK


def _main_rl(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from cake_drake.learning.policies.checkpoint import RL_PIP, require_rl_packages
    from cake_drake.outputs.files import OutputDir
    from cake_drake.scenario import load_scenario

    require_rl_packages("train --rl")
    try:  # Gymnasium and Stable-Baselines3 at its import: optional extras
        from cake_drake.learning.training import rl
    except ModuleNotFoundError as e:
        raise InputError(f"train --rl needs {e.name}, which is not installed: {RL_PIP}") from None

    if args.dataset:
        raise InputError(f"{args.dataset[0]}: --rl reads no dataset (it learns from the "
                         "reward of its own episodes)")  # fmt: skip
    if args.device not in ("auto", "cpu"):
        raise InputError(f"--device {args.device} with --rl: it trains on the CPU")
    if not args.name:
        raise InputError(f"--rl {args.rl} without --name: name the task to learn")
    scenario = load_scenario(args.rl, args.name, args.set)
    recipe = scenario.training.rl
    given = {"steps": args.steps, "base": args.base, "algorithm": args.algorithm,
             "envs": args.envs}  # fmt: skip
    recipe = rl.check_recipe(replace(recipe, **{k: v for k, v in given.items() if v is not None}))
    cluster = ray_engine(args.ray, recipe.envs)  # an address nothing answers at: refused here
    if scenario.motion.skills:  # a residual on a skill, one place an episode
        from cake_drake.learning.skills.residual import FILES
        from cake_drake.learning.skills.train_residual import train_skill_rl as train
    else:
        FILES, train = rl.FILES, rl.train_rl
    with OutputDir(args.out, "train --rl", FILES, [args.rl]) as staged:
        info = train(scenario, args.name, staged, recipe, args.seed,
                     log=lambda line: print(line, flush=True), cluster=cluster)  # fmt: skip
        staged.commit()
    if info["kind"] == "skill_residual":
        step = info["kept"].rsplit(" ", 1)[-1]
        kept = next((c for c in info["checks"] if str(c["steps"]) == step), None)
        said = "" if kept is None else (f" ({kept['placed']}/{kept['of']} held-out places "
                                        f"within 5 mm, {kept['p95_mm']:.2f} mm p95)")  # fmt: skip
        print(f"{args.out}: skill + RL residual ({info['algorithm'].upper()}) on "
              f"{args.name}, {info['steps']} steps in {info['minutes']:.1f} min "
              f"({info['steps_per_s']:.0f} steps/s), {info['kept']}{said}")  # fmt: skip
        return EXIT_OK
    won, of = info["last_episodes_success"]
    print(
        f"{args.out}: {rl.KIND_LABELS[info['kind']]} ({info['algorithm'].upper()}) on "
        f"{args.name}, {info['steps']} steps in {info['minutes']:.1f} min "
        f"({info['steps_per_s']:.0f} steps/s); the last {of} episodes: {won} succeeded"
    )
    return EXIT_OK


def _main_planner(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from cake_drake.learning.training.planner import PlannerRecipe, check_recipe, train_planner

    if args.reward:
        return _main_planner_reward(args)
    if args.dataset:
        raise InputError(f"{args.dataset[0]}: --planner reads no dataset (its labels are "
                         "computed exactly from enumerated states)")  # fmt: skip
    if args.device not in ("auto", "cpu"):
        raise InputError(f"--device {args.device} with --planner: it trains on the CPU")
    recipe = PlannerRecipe(seed=args.seed)
    given = {"steps": args.steps, "batch_size": args.batch_size}
    if args.blocks is not None:
        given.update(min_blocks=args.blocks[0], max_blocks=args.blocks[1])
    recipe = replace(recipe, **{k: v for k, v in given.items() if v is not None})
    check_recipe(recipe)
    from cake_drake.learning.training.planner import FILES
    from cake_drake.outputs.files import OutputDir

    with OutputDir(args.out, "train --planner", FILES) as staged:
        info = train_planner(recipe, staged, log=lambda line: print(line, flush=True))
        staged.commit()
    print(
        f"{args.out}: learned planner trained {recipe.steps} steps on {info['states']} states "
        f"of {recipe.min_blocks}-{recipe.max_blocks} blocks in {info['minutes']:.1f} min; "
        f"plan with --planner learned@{args.out}"
    )
    return EXIT_OK


def _main_planner_reward(args: argparse.Namespace) -> int:
    from dataclasses import replace

    from cake_drake.learning.training.planner import FILES
    from cake_drake.learning.training.planner_reward import (
        RewardRecipe,
        check_recipe,
        train_planner_reward,
    )
    from cake_drake.outputs.files import OutputDir

    if args.dataset:
        raise InputError(f"{args.dataset[0]}: --planner --reward reads no dataset (it learns "
                         "from the goal's reward in its own episodes)")  # fmt: skip
    if args.device not in ("auto", "cpu"):
        raise InputError(f"--device {args.device} with --planner: it trains on the CPU")
    given = {"steps": args.steps, "problems": args.batch_size, "seed": args.seed}
    if args.blocks is not None:
        given.update(min_blocks=args.blocks[0], max_blocks=args.blocks[1])
    recipe = replace(RewardRecipe(), **{k: v for k, v in given.items() if v is not None})
    check_recipe(recipe)
    with OutputDir(args.out, "train --planner --reward", FILES) as staged:
        info = train_planner_reward(recipe, staged, log=lambda line: print(line, flush=True))
        staged.commit()
    print(
        f"{args.out}: learned planner trained from the reward alone, {recipe.steps} steps, "
        f"{info['episodes']} episodes ({info['states']} states) of {recipe.min_blocks}-"
        f"{recipe.max_blocks} blocks in {info['minutes']:.1f} min; plan with --planner "
        f"learned@{args.out}"
    )
    return EXIT_OK


def _main_dagger(args: argparse.Namespace, recipe) -> int:
    from cake_drake.learning.training.dagger import check_rounds, dagger, dagger_outputs, source
    from cake_drake.outputs.files import OutputDir

    per_round = EPISODES_PER_ROUND if args.episodes_per_round is None else args.episodes_per_round
    beta = 0.0 if args.beta is None else args.beta
    check_rounds(args.dagger, per_round, beta, args.round_steps)
    source(args.dataset)  # the task to roll out on, named first where it is missing
    if recipe.inputs == "relative":
        check_relative(args, recipe)
    workers = worker_count(args.workers)
    # Every round is written into the staging folder and put in place at the end: an
    # error or Ctrl-C in any round leaves OUT as it was.
    names = dagger_outputs(recipe.inputs)
    with OutputDir(args.out, "train --dagger", names, [args.dataset]) as staged:
        summary = dagger(
            args.dataset, staged.staging, recipe, args.dagger, per_round, beta, args.device,
            args.seed, workers, ray_engine(args.ray, workers), args.weights, args.round_steps,
            log=lambda line: print(line, flush=True), final=staged.real,
        )  # fmt: skip
        staged.commit()
    where = (f"run it with motion.skills: {args.out}" if recipe.inputs == "relative"
             else f"checkpoint {args.out}/checkpoints/last/pretrained_model")  # fmt: skip
    print(
        f"{args.out}: {recipe.policy} ({recipe.inputs}) trained on {args.dataset} and "
        f"{args.dagger} rounds of DAgger ({summary['dagger']['expert_labelled_frames']} "
        f"expert-labelled frames); {where}"
    )
    return EXIT_OK


#: What every mode reads: DATASET (each mode says what it does with it), --out, --traceback.
EVERY_MODE = frozenset({"dataset", "out", "traceback"})
#: What a policy's training reads, with --dagger's rounds or without.
POLICY_READS = frozenset(
    {"policy", "inputs", "cameras", "steps", "batch_size", "device", "seed", "weights"}
)
#: train's modes, each with the flags it reads; the first whose flag is given is chosen.
MODES: tuple[Mode, ...] = (
    Mode(
        chooser="rl",
        whose="RL's",
        reads=frozenset(
            {"rl", "name", "base", "algorithm", "envs", "steps", "device", "seed", "ray", "set"}
        ),
        refusal="it is not one of RL's settings (the task's training.rl recipe has them)",
        main=_main_rl,
    ),
    Mode(
        chooser="planner",
        whose="the learned planner's",
        reads=frozenset({"planner", "reward", "blocks", "steps", "batch_size", "device", "seed"}),
        refusal="it is a policy's setting, not the learned planner's",
        main=_main_planner,
    ),
    Mode(
        chooser="perception",
        whose="the learned eyes'",
        reads=frozenset({"perception", "minutes", "steps", "batch_size", "device", "seed"}),
        refusal="it is a policy's setting, not the learned eyes'",
        main=_main_perception,
    ),
    Mode(
        chooser="residual",
        whose="the residual's",
        reads=frozenset({"residual"}),
        refusal="it is a policy's setting; a residual is fitted by least squares",
        main=_main_residual,
    ),
    Mode(
        chooser="dagger",
        whose="DAgger's",
        reads=POLICY_READS
        | {"dagger", "episodes_per_round", "beta", "round_steps", "workers", "ray"},
        refusal="DAgger starts its folder afresh",
        main=_main_policy,
    ),
    Mode(
        chooser=None,
        whose="a policy's",
        reads=POLICY_READS | {"resume"},
        refusal="it is not a policy's setting",
        main=_main_policy,
    ),
)
