"""Recordings: episodes as LeRobot datasets, and the batches trained on them.

:mod:`.dataset` is the format (features, layout, the checked reader; written and read by
lerobot itself), :mod:`.recording` the loops that record demonstrations and replay them,
:mod:`.batches` the data path under LeRobot's training loop (columns read once,
gathered by index), and :mod:`.frames` the learned eyes' sightings (every cube the
perception cameras saw in runs, with its true pose). Nothing here trains or acts.
"""
