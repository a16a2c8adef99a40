"""Plan a PDDL problem and print the plan (defaults: Blocksworld, problem_5).

Prints one action per line, then a one-line note: planner, search,
heuristic, length (optimal or satisficing) and time. The default planner,
auto, runs A* with LM-cut (optimal) within a budget of about three seconds,
then weighted A* and greedy best-first with hFF (satisficing); the note says
which one produced the plan and whether it is proved optimal.

The optimal plan for problem_5 has 10 actions. A satisficing planner returns
whatever plan it finds first, which may be longer: gbfs-ff returns 14, and the
"12" quoted by the exercise can only come from such a search.

exit codes: 0 plan found; 1 no plan (proved unsolvable, or the time limit
was reached -- the message says which); 2 bad input (files, options).
"""

import sys

from cake_drake.cli import main_plan
from cake_drake.errors import run_cli

if __name__ == "__main__":
    sys.exit(run_cli(main_plan))
