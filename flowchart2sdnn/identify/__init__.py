"""Identification: fit a chart to measured data (offline LM, multi-start, quasi-online).

Modules: :mod:`.settings` -> :mod:`.run` (identify) -> :mod:`.result` (the typed answer) <-> :mod:`.document`
(RESULT.json); :mod:`.workers` (the one way a start is fitted), :mod:`.problem`, :mod:`.evidence`,
:mod:`.online`, :mod:`.summary` (text), :mod:`.plots`.

Layer 5: imports the compiler, network, fit, data, chart and executors below it; never diagnose, batch or cli.
"""
