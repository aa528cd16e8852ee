"""Multiple shooting: segments of a record fitted with free starts, merged stage by stage into single shooting.

:mod:`.multiple` (the staged fit, merging until single shooting) over :mod:`.segmented` (one stage's problem:
the residual and sparse Jacobian of the segments and their free starts), and :mod:`.auto` (``--shooting auto``:
whether a record's chart forgets a moved start, and the second look).

The package's names are reached through :mod:`flowchart2sdnn.identify`; this file imports nothing.
"""
