"""Identification: fit a chart to measured data (offline LM, multi-start, quasi-online).

Modules: :mod:`.settings` -> :mod:`.run` (identify) -> :mod:`.result` (the typed answer) -> :mod:`.serialize`
(RESULT.json written); :mod:`.document` reads it back; :mod:`.workers` (the one way a start is fitted),
:mod:`.problem`, :mod:`.evidence`, :mod:`.online`. The text, pages and figures live in
:mod:`flowchart2sdnn.report`.

Layer 5: imports the compiler, network, fit, data, chart and executors below it; never diagnose, batch, report
or cli.
"""
