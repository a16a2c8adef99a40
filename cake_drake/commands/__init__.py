"""The commands, one module a command: its doc, its parser and its main.

``cake-drake COMMAND ...`` (:mod:`cake_drake.cli`, the table of commands) or ``python -m
cake_drake.COMMAND ...`` runs ``main_COMMAND`` of :mod:`cake_drake.commands.COMMAND` for
the commands ``run``, ``gains``, ``sweep``, ``world``, ``plan``, ``validate``, ``saycan``,
``record``, ``evaluate`` and ``train``; :mod:`.common` holds what their parsers share.
Flags choose and override; they carry no logic: ``run``'s flags only write fields of a
:class:`~cake_drake.scenario.Scenario`, and everything a flag can do a scenario file can
do too. The library never imports this package.

Exit codes (every command): 0 success; 1 no plan, or an invalid plan; 2 bad input
(one line on stderr, nothing written); 3 the plan could not be executed in the
simulated world; 4 the outputs could not be written (nothing was); 130 interrupted by
Ctrl-C or SIGTERM (nothing was written).
"""

import time

#: When the command began loading: every entry point imports this package before any
#: command, so ``run`` measures its import time from here.
STARTED = time.perf_counter()
