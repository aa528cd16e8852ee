"""Multiple shooting: segments of a record fitted with free starts, merged stage by stage into single shooting.

:mod:`.multiple` (the segmented problem and the staged fit) and :mod:`.auto` (``--shooting auto``: whether a
record's chart forgets a moved start, and the second look).

The package's names are reached through :mod:`flowchart2sdnn.identify`; this file imports nothing.
"""
