"""`sdnn diagnose`: trace the residual to a missing effect, add it to the chart, refit, report before and after.

Pipeline: residual tests (:mod:`.residual`) -> the effects library (:mod:`.effects`, :mod:`.usereffects`) ->
the score test of every candidate (:mod:`.score`) -> brief refits and acceptance (:mod:`.loop`) -> text
report (:mod:`.report`); the click command lives in :mod:`.cli`.
"""

from .effects import (
    BUILTIN_EFFECTS,
    Backlash,
    Cogging,
    Damping,
    DeadTime,
    DeadZone,
    Effect,
    Friction,
    Saturation,
    Scales,
)
from .graph import Place
from .loop import DiagnoseSettings, Diagnosis, Fitted, diagnose
from .score import Candidate, Score, Screen, gauss_newton_decrease, screen
from .usereffects import YamlEffect, load_effects_file

__all__ = [
    "BUILTIN_EFFECTS",
    "Backlash",
    "Candidate",
    "Cogging",
    "Damping",
    "DeadTime",
    "DeadZone",
    "DiagnoseSettings",
    "Diagnosis",
    "Effect",
    "Fitted",
    "Friction",
    "Place",
    "Saturation",
    "Scales",
    "Score",
    "Screen",
    "YamlEffect",
    "diagnose",
    "gauss_newton_decrease",
    "load_effects_file",
    "screen",
]
