"""A sweep file: a base scenario, axes over its fields and seeds; one scenario per run.

::

    description: success as the number of blocks grows
    base: ../scenarios/exercise.yaml        # optional; or {file: ..., name: position}
    scenario:                               # optional: fields over the base
      outputs: {render: false}
    grid:                                   # every combination, in file order
      task.generate.blocks: [3, 4, 5]
      controller.kd: [[20], [5]]
    cases:                                  # optional: settings, each crossed with the grid
      - {name: exercise, task.generate.style: exercise}
      - {name: ipc, task.generate.style: ipc, task.domain: ../pddl/variants/blocksworld-ipc.pddl}
    seeds: 2                                # the scenario's seed: 0..N-1, or a list [0, 7]
    collect: [logs]                         # optional collectors run in the worker

A case may have a ``name`` (the ``case`` column and the plots' legend; else its number).
An axis names a scenario field by its dotted path (``world.time_step``, ``task.planner``,
``controller.kd``, ``seed``); every path is checked against the :class:`Scenario` tree
and every value against the field's type before anything runs, and a bad one is one
:class:`InputError` line naming the file, the line and the valid fields.
"""

from __future__ import annotations

import dataclasses
import hashlib
import itertools
import typing
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from pydrake.common.yaml import yaml_dump_typed, yaml_load_typed

from cake_drake.errors import InputError
from cake_drake.scenario import (
    Scenario,
    _check_node,
    _fields,
    _top_level,
    _union_members,
    _where,
    load_scenario,
    resolve_path,
    resolved,
)

#: The most runs one sweep may hold (checked before it is expanded).
MAX_RUNS = 10_000
SWEEP_KEYS = ("description", "base", "scenario", "grid", "cases", "seeds", "collect")
#: Fields a sweep sets itself: every run writes to its own folder.
RESERVED = ("outputs.folder",)

Setting = tuple[str, yaml.Node]  # (dotted path, value node)


@dataclass
class Run:
    """One run of a sweep: its parameters and its scenario (outputs folder not yet set)."""

    index: int
    params: dict[str, object]  # column -> value, for the results table
    scenario: Scenario
    id: str = ""


@dataclass
class Sweep:
    """A base scenario, a grid of axes, a list of cases and seeds: :meth:`runs` expands it."""

    base: Scenario = field(default_factory=Scenario)
    grid: list[tuple[str, list[yaml.Node]]] = field(default_factory=list)
    cases: list[list[Setting]] = field(default_factory=list)
    case_names: list[str] = field(default_factory=list)
    seeds: list[int] | None = None
    collect: list[str] = field(default_factory=list)
    description: str = ""
    source: str = "<sweep>"
    folder: Path | None = None  # relative paths in values are taken from here
    text: str = ""  # the file as written, copied to the sweep's output folder

    @classmethod
    def of(
        cls,
        base: Scenario,
        grid: dict[str, list] | None = None,
        cases: list[dict[str, object]] | None = None,
        seeds: int | list[int] | None = None,
        collect: list[str] | None = None,
        description: str = "",
    ) -> Sweep:
        """A sweep from Python values (checked as a file's would be)."""
        sweep = cls(base=base, collect=list(collect or []), description=description)
        for path, values in (grid or {}).items():
            where = f"{sweep.source}: grid"
            field_type = check_path(path, base, where)
            if not values:
                raise InputError(f"{where}: axis {path} is empty; give one or more values")
            nodes = [_node(v) for v in values]
            for n in nodes:
                _check_node(n, field_type, sweep.source, path)
            sweep.grid.append((path, nodes))
        for case in cases or []:
            settings = []
            sweep.case_names.append(str(case.get("name", len(sweep.case_names))))
            for path, value in case.items():
                if path == "name":
                    continue
                field_type = check_path(path, base, f"{sweep.source}: cases")
                node = _node(value)
                _check_node(node, field_type, sweep.source, path)
                settings.append((path, node))
            sweep.cases.append(settings)
        sweep.seeds = _seed_list(seeds, sweep.source) if seeds is not None else None
        sweep._check_unique()
        return sweep

    @property
    def size(self) -> int:
        """How many runs the sweep is, computed without expanding it."""
        n = max(len(self.cases), 1) * (len(self.seeds) if self.seeds is not None else 1)
        for _, values in self.grid:
            n *= len(values)
        return n

    def runs(self) -> list[Run]:
        """Every run, in order: cases, then the grid's combinations, then seeds."""
        out = []
        combos = list(itertools.product(*[[(p, v) for v in vs] for p, vs in self.grid]))
        names = self.case_names or [None]
        for name, case in zip(names, self.cases or [[]], strict=True):
            for combo in combos:
                for seed in self.seeds if self.seeds is not None else [None]:
                    settings = list(case) + list(combo)
                    if seed is not None:
                        settings.append(("seed", _node(seed)))
                    scenario = self.base
                    for path, node in settings:
                        scenario = apply(scenario, path, node)
                    scenario = resolved(scenario, self.folder)
                    paths = [p for p in self.columns if p != "case"]
                    params = {p: _label(getattr_path(scenario, p)) for p in paths}
                    params = {"case": name, **params} if self.cases else params
                    out.append(Run(len(out), params, scenario))
        return out

    def check(self) -> None:
        """Every value the sweep will run, through the run's own check (:func:`pipeline.check`),
        without expanding the grid: the base, each case, and each axis value on the base
        (with the first case, where there are cases). One line naming the value, exit 2."""
        from cake_drake.pipeline import check

        def checked(settings, what: str) -> None:
            scenario = self.base
            for path, node in settings:
                scenario = apply(scenario, path, node)
            try:
                check(resolved(scenario, self.folder), write=False)
            except InputError as e:
                raise InputError(f"{self.source}: {what}: {e}") from None

        cases = list(zip(self.case_names, self.cases, strict=True)) or [(None, [])]
        for name, case in cases:
            checked(case, f"case {name}" if name is not None else "the base scenario")
        first = cases[0][1]
        for path, values in self.grid:
            for node in values:
                checked([*first, (path, node)], f"grid {path} = {_label_node(node)}")

    @property
    def columns(self) -> list[str]:
        """The parameter columns: every path a case, the grid or the seeds set."""
        cols: list[str] = ["case"] if self.cases else [""]
        for case in self.cases:
            cols += [p for p, _ in case if p not in cols]
        cols += [p for p, _ in self.grid if p not in cols]
        if self.seeds is not None:
            cols.append("seed")
        return [c for c in cols if c]

    @property
    def plot_axes(self) -> list[str]:
        """What the plots put on x: each grid axis (the cases when there is no grid)."""
        axes = [p for p, _ in self.grid if p != "seed"]
        return axes or (["case"] if self.cases else [])

    def _check_unique(self) -> None:
        if self.size > MAX_RUNS:
            raise InputError(
                f"{self.source}: {self.size:,} runs (cases x grid x seeds) is more than one "
                f"sweep holds ({MAX_RUNS:,}); split it into several sweeps"
            )
        grid_paths = [p for p, _ in self.grid]
        twice = sorted({p for p in grid_paths if grid_paths.count(p) > 1})
        if twice:
            raise InputError(f"{self.source}: grid names {', '.join(twice)} twice; keep one")
        case_paths = {p for case in self.cases for p, _ in case}
        both = sorted(set(grid_paths) & case_paths)
        if both:
            raise InputError(
                f"{self.source}: {', '.join(both)} set by both grid and cases; keep one"
            )
        if self.seeds is not None and "seed" in set(grid_paths) | case_paths:
            raise InputError(f"{self.source}: seed is set by both seeds and an axis; keep one")


# --- paths and values --------------------------------------------------------------------


def check_path(path: str, base: Scenario, where: str) -> object:
    """The type of the scenario field at ``path``; one line naming the valid fields if none.

    A field whose type is a union of configs (``controller``) is read as the base's
    concrete type (``controller.kd`` for a ``!ComputedTorque``).
    """
    if path in RESERVED:
        raise InputError(f"{where}: {path} is set by the sweep (each run has its own folder)")
    tp: object = Scenario
    obj: object = base
    walked: list[str] = []
    for part in path.split("."):
        variant = _variants(tp) > 1
        tp = _concrete(tp, obj)
        here = ".".join(walked)
        if dataclasses.is_dataclass(tp):
            fields = _fields(tp)
            if part not in fields:
                of = f" of {here}" + (f" (!{tp.__name__})" if variant else "")
                raise InputError(
                    f"{where}: unknown field {path!r}; valid fields{of if here else ''}: "
                    f"{', '.join(fields)}"
                )
            tp, obj = fields[part], getattr(obj, part, None)
        elif typing.get_origin(tp) is dict:
            tp = typing.get_args(tp)[1]
            obj = obj.get(part) if isinstance(obj, dict) else None
        else:
            name = getattr(tp, "__name__", str(tp))
            raise InputError(f"{where}: unknown field {path!r}: {here} is a {name}, not a mapping")
        walked.append(part)
    return tp


def _variants(tp: object) -> int:
    """How many config types a field's union holds (``controller``: three)."""
    return sum(dataclasses.is_dataclass(m) for m in _union_members(tp))


def _concrete(tp: object, obj: object) -> object:
    """A union of dataclasses as the type of ``obj`` (or its first member); Optional[T] as T."""
    members = _union_members(tp)
    if not members:
        return tp
    classes = [m for m in members if dataclasses.is_dataclass(m)]
    if classes:
        return type(obj) if type(obj) in classes else classes[0]
    others = [m for m in members if m is not type(None)]
    return others[0]


def getattr_path(scenario: Scenario, path: str) -> object:
    obj: object = scenario
    for part in path.split("."):
        obj = obj.get(part) if isinstance(obj, dict) else getattr(obj, part, None)
    return obj


def apply(scenario: Scenario, path: str, node: yaml.Node) -> Scenario:
    """A copy of ``scenario`` with the field at ``path`` set to the YAML value ``node``.

    Drake's typed loader merges the value onto the scenario; where the path goes through
    a union of configs, the mapping is tagged with the scenario's own type, so that
    ``controller.kd`` changes the gains of the controller there and keeps the rest.
    """
    parts = path.split(".")
    chain = []  # (declared type, current value) of each field along the path but the last
    tp: object = Scenario
    obj: object = scenario
    for part in parts[:-1]:
        concrete = _concrete(tp, obj)
        if dataclasses.is_dataclass(concrete):
            tp = _fields(concrete)[part]
        else:  # a dict[str, T]
            tp = typing.get_args(concrete)[1]
        obj = obj.get(part) if isinstance(obj, dict) else getattr(obj, part, None)
        chain.append((tp, obj))
    value = node
    for part, (tp_i, obj_i) in reversed(list(zip(parts[1:], chain, strict=True))):
        tag = "tag:yaml.org,2002:map"
        if _variants(tp_i) > 1 and obj_i is not None:
            tag = f"!{type(obj_i).__name__}"
        value = yaml.MappingNode(tag, [(_key(part), value)])
    root = yaml.MappingNode("tag:yaml.org,2002:map", [(_key(parts[0]), value)])
    text = yaml.serialize(root, Dumper=yaml.SafeDumper)
    return yaml_load_typed(schema=Scenario, data=text, defaults=scenario)


def _key(name: str) -> yaml.ScalarNode:
    return yaml.ScalarNode("tag:yaml.org,2002:str", name)


def _node(value: object) -> yaml.Node:
    if isinstance(value, yaml.Node):
        return value
    return yaml.compose(yaml.safe_dump(value), Loader=yaml.SafeLoader)


def _label(value: object) -> object:
    """A table cell for a parameter: a scalar, a one-element list's item, else short text."""
    if isinstance(value, list | tuple) and len(value) == 1:
        value = value[0]
    if value is None or isinstance(value, bool | int | float | str):
        return value
    if dataclasses.is_dataclass(value):
        return f"!{type(value).__name__}"
    return yaml.safe_dump(value, default_flow_style=True, width=10**6).strip()


def _label_node(node: yaml.Node) -> str:
    text = yaml.serialize(node, Dumper=yaml.SafeDumper).strip().removesuffix("...").strip()
    return text if len(text) <= 40 else text[:37] + "..."


def run_id(run: Run, collect: list[str]) -> str:
    """A stable name for a run: its index and a hash of everything that shapes it."""
    text = yaml_dump_typed(run.scenario) + "\n".join(collect)
    return f"{run.index:04d}-{hashlib.sha1(text.encode()).hexdigest()[:8]}"


def _seed_list(value: object, where: str) -> list[int]:
    if isinstance(value, bool):
        raise InputError(f"{where}: seeds is a count (e.g. 3) or a list of integers")
    if isinstance(value, int):
        if value < 1:
            raise InputError(f"{where}: seeds = {value} runs nothing; give a count >= 1")
        if value > MAX_RUNS:
            raise InputError(f"{where}: seeds = {value} is more than {MAX_RUNS:,} runs")
        return list(range(value))
    if (
        isinstance(value, list)
        and value
        and all(isinstance(v, int) and not isinstance(v, bool) for v in value)
    ):
        return list(value)
    raise InputError(f"{where}: seeds is a count (e.g. 3) or a non-empty list of integers")


# --- the file ----------------------------------------------------------------------------


def load_sweep(path: str | Path) -> Sweep:
    """Read and check a sweep file (see the module's docstring for the format)."""
    from cake_drake.symbolic.sexpr import read_text

    path = Path(path)
    text = read_text(path, "sweep file (*.yaml)")
    return parse_sweep(text, str(path), path.resolve().parent)


def parse_sweep(text: str, source: str = "<sweep>", folder: Path | None = None) -> Sweep:
    root = _top_level(text, source)
    if not isinstance(root, yaml.MappingNode):
        raise InputError(f"{source}: a sweep file is a mapping of {', '.join(SWEEP_KEYS)}")
    entries: dict[str, yaml.Node] = {}
    for key_node, value_node in root.value:
        key = key_node.value
        if key not in SWEEP_KEYS:
            raise InputError(
                f"{_where(source, key_node)}: unknown key {key!r} in the sweep; "
                f"valid keys: {', '.join(SWEEP_KEYS)}"
            )
        if key in entries:
            raise InputError(f"{_where(source, key_node)}: key {key!r} given twice")
        entries[key] = value_node
    base = _base(entries.get("base"), source, folder)
    if "scenario" in entries:
        node = entries["scenario"]
        _check_node(node, Scenario, source, "")
        check_path_nodes(node, source)
        base = yaml_load_typed(
            schema=Scenario, data=yaml.serialize(node, Dumper=yaml.SafeDumper), defaults=base
        )
    sweep = Sweep(base=base, source=source, folder=folder, text=text)
    if "description" in entries:
        sweep.description = str(_plain(entries["description"]))
    if "grid" in entries:
        grid = entries["grid"]
        if not isinstance(grid, yaml.MappingNode):
            raise InputError(f"{_where(source, grid)}: grid is a mapping of field: [values]")
        for key_node, values in grid.value:
            axis = key_node.value
            where = _where(source, key_node)
            field_type = check_path(axis, base, where)
            if not isinstance(values, yaml.SequenceNode):
                raise InputError(f"{where}: axis {axis} needs a list of values, e.g. [1, 2]")
            if not values.value:
                raise InputError(f"{where}: axis {axis} is empty; give one or more values")
            for v in values.value:
                _check_node(v, field_type, source, axis)
            sweep.grid.append((axis, list(values.value)))
    if "cases" in entries:
        cases = entries["cases"]
        if not isinstance(cases, yaml.SequenceNode) or not cases.value:
            raise InputError(
                f"{_where(source, cases)}: cases is a non-empty list of {{field: value, ...}}"
            )
        for case in cases.value:
            if not isinstance(case, yaml.MappingNode) or not case.value:
                raise InputError(f"{_where(source, case)}: a case is a mapping of field: value")
            settings = []
            name = str(len(sweep.case_names))
            for key_node, v in case.value:
                if key_node.value == "name":
                    name = str(_plain(v))
                    continue
                field_type = check_path(key_node.value, base, _where(source, key_node))
                _check_node(v, field_type, source, key_node.value)
                settings.append((key_node.value, v))
            sweep.cases.append(settings)
            sweep.case_names.append(name)
    if "seeds" in entries:
        node = entries["seeds"]
        sweep.seeds = _seed_list(_plain(node), _where(source, node))
    if "collect" in entries:
        node = entries["collect"]
        value = _plain(node)
        if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
            raise InputError(f"{_where(source, node)}: collect is a list of collector names")
        from cake_drake.plugins import resolve
        from cake_drake.sweeps.collect import COLLECTORS

        for spec in value:
            resolve(spec, COLLECTORS, "collector")
        sweep.collect = value
    sweep._check_unique()
    return sweep


def check_path_nodes(node: yaml.MappingNode, source: str) -> None:
    """Refuse ``scenario: {outputs: {folder: ...}}``: the sweep names every run's folder."""
    for key_node, value in node.value:
        if key_node.value == "outputs" and isinstance(value, yaml.MappingNode):
            for k, _ in value.value:
                if k.value == "folder":
                    raise InputError(
                        f"{_where(source, k)}: outputs.folder is set by the sweep "
                        "(each run has its own folder under --out)"
                    )


def _plain(node: yaml.Node) -> object:
    try:
        return yaml.safe_load(yaml.serialize(node, Dumper=yaml.SafeDumper))
    except yaml.YAMLError:
        return None


def _base(node: yaml.Node | None, source: str, folder: Path | None) -> Scenario:
    if node is None:
        return Scenario()
    value = _plain(node)
    if isinstance(value, str):
        file, name = value, None
    elif isinstance(value, dict) and set(value) <= {"file", "name"} and "file" in value:
        file, name = value["file"], value.get("name")
    else:
        raise InputError(
            f"{_where(source, node)}: base is a scenario file, or {{file: FILE, name: NAME}}"
        )
    return load_scenario(resolve_path(str(file), folder), name)
