"""Outputs are written whole or not at all: staged in a hidden folder, then moved in."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

from cake_drake.errors import InputError


class OutputDir:
    """Stage files under ``out/.staging-<pid>/``; :meth:`commit` moves them into ``out``."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        try:
            self.out.mkdir(parents=True, exist_ok=True)
            self.staging = self.out / f".staging-{os.getpid()}"
            self.staging.mkdir(exist_ok=True)
        except OSError as e:
            raise InputError(f"{out}: cannot create the output folder ({e.strerror})") from None
        self.names: list[str] = []

    def path(self, name: str) -> Path:
        self.names.append(name)
        return self.staging / name

    def write_json(self, name: str, data: object) -> None:
        self.path(name).write_text(json.dumps(data, indent=2, sort_keys=False) + "\n")

    def commit(self) -> list[Path]:
        written = []
        for name in self.names:
            src = self.staging / name
            if src.exists():
                os.replace(src, self.out / name)
                written.append(self.out / name)
        self.discard()
        return written

    def discard(self) -> None:
        shutil.rmtree(self.staging, ignore_errors=True)
