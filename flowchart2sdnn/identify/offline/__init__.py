"""The offline fit: one chart, its records, Levenberg-Marquardt with RTRL Jacobians from many starts.

:mod:`.run` (identify: the whole offline answer) builds a :mod:`.problem` (the chart compiled against its
records), runs the optimizer by :mod:`.optimize` and makes the answer's pieces by :mod:`.assemble`; every start
is fitted through :mod:`.workers` (the one way a start is fitted), with the learned curves'
start of :mod:`.curvestart` and the spans of :mod:`.curvespan`, the initial states of :mod:`.initstate` and
the per-record values of :mod:`.perrecord`; :mod:`.arrays` holds the record-to-array helpers they share.

The package's names are reached through :mod:`flowchart2sdnn.identify`; this file imports nothing.
"""
