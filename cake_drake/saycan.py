"""Map a SayCan transcript onto a PDDL kitchen domain and show where STRIPS breaks.

Reads the robot's numbered steps and maps each through a small lexicon: a skill
phrase stands for HTN-style methods, and the first whose precondition holds in
the current state decides the ground actions ("put down X" where an open
container stands is put-in). Simulates the steps against the problem and prints
a per-step verdict: maps cleanly; maps via a method (which fired, and why);
maps to several actions; precondition fails (with the unmet facts); ambiguous
(a noun naming several objects, with the candidates); no schema (verb or object
not in the domain, with the vocabulary). Then checks the goal, plans the same
problem, shows both plans side by side and ends with a note: what mapped, what
did not and why, what would have been needed. Writes plan.txt (the transcribed
PDDL plan), problem.pddl and report.md to --out.

Without --problem SayCan's own kitchen is used (its 15 objects, close and far
counter, table, trash can, bowl, the user). It has no goal: the transcript's
"Goal:" line, if any, supplies one; otherwise only executability is checked.

exit codes: 0 the transcribed plan is valid and reaches the goal (or, without
a goal, every step executes); 1 it maps but fails (no schema, ambiguous, a
precondition fails, or the goal is not reached); 2 unreadable input.
"""

import sys

from cake_drake.cli import main_saycan
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_saycan))
