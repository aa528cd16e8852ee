"""Which stop rule ended a Levenberg-Marquardt fit, in one sentence with its numbers.

:data:`~flowchart2sdnn.fit.lm.STATUS_MESSAGES` says what a status word means, naming every rule that can give
it ("small_cost_change" has four); the message's detail (``(iteration 23, cost 0.15, mu 0.01, <detail>)``)
says which one fired. :func:`stop_rule` reads the two back into the one rule, for a status line a newcomer can
act on. The message itself is unchanged (RESULT.json keeps it).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .stopping import CRAWL_DETAIL, STATUS_MESSAGES

__all__ = ["StopRule", "stop_rule", "status_line"]

#: the tail lm.levenberg_marquardt appends to STATUS_MESSAGES[status]
_TAIL = re.compile(r" \(iteration (?P<it>\d+), cost (?P<cost>[^,()]+), mu [^,()]+(?:, (?P<detail>[^()]*))?\)"
                   r"(?P<guard>; last step refused by the guard: .*)?$")

#: status -> (the setting whose test fired, the sentence) where one rule gives the status
_ONE_RULE = {
    "min_grad": ("min_grad", "the gradient norm fell below min_grad"),
    "cost_goal": ("cost_goal", "the cost reached cost_goal"),
    "max_iter": ("max_iter", "the iteration limit max_iter was reached"),
    "mu_max": ("mu_max", "the damping mu grew past mu_max: no damped step lowers the cost (a minimum, or "
                         "steps refused)"),
    "max_mu_tries": ("max_mu_tries", "max_mu_tries raises of the damping in a row found no step that lowers the "
                                     "cost"),
    "small_step": ("min_rel_step", "the step fell below min_rel_step of the parameters"),
    "callback_stop": ("stop", "stopped on request"),
    "cut_off": ("cutoff", "cut off: at its pace it could no longer reach the best refit of its round"),
    "interrupted": ("stop", "interrupted; the best point so far is kept"),
}

_OVER = re.compile(r"(?P<x>\S+) of the cost over the last (?P<n>\d+) iterations")


@dataclass(frozen=True)
class StopRule:
    """The rule that ended a fit: `rule`, the setting whose test fired (``"stall_decrease"``); `sentence`, what
    happened, with the numbers the message gave; `iterations` and `cost` at the end (None when unknown)."""

    rule: str
    sentence: str
    iterations: int | None = None
    cost: float | None = None


def _small_cost_change(detail: str) -> tuple[str, str]:
    if detail.startswith("relative decrease "):
        x = detail.removeprefix("relative decrease ")
        return "min_rel_cost_change", f"the last iteration lowered the cost by only {x} of itself " \
                                      "(min_rel_cost_change)"
    if detail.startswith(CRAWL_DETAIL):
        m = _OVER.search(detail)
        if m:
            return "crawl_decrease", (f"at the noise floor the cost fell by only {m['x']} of itself over the last "
                                      f"{m['n']} iterations (crawl_decrease)")
    m = _OVER.fullmatch(detail)
    if m:
        return "stall_decrease", (f"the cost fell by only {m['x']} of itself over the last {m['n']} iterations "
                                  "(stall_decrease)")
    if "rounding" in detail:
        return "rounding", "the best decrease the model predicts is below the cost's rounding"
    return "small_cost_change", f"the cost stopped falling ({detail})"


def stop_rule(status: str, message: str) -> StopRule | None:
    """The rule behind `status` and an LM `message`, or None when `message` is not an LM message as
    ``levenberg_marquardt`` writes it (quasi-online runs, no_excitation, a message of another kind)."""
    if status not in STATUS_MESSAGES or status == "diverged_at_start":
        return None
    m = _TAIL.search(message)
    if m is None:
        return None
    detail = m["detail"] or ""
    if status in _ONE_RULE:
        rule, sentence = _ONE_RULE[status]
    elif status == "small_cost_change":
        rule, sentence = _small_cost_change(detail) if detail else ("small_cost_change", "the cost stopped falling")
    elif status == "negligible_gain":
        pace = "gained by the last" in detail.split(",")[0]
        rule = "negligible_pace" if pace else "negligible_gain"
        sentence = f"what is left to gain is negligible ({rule})" + (f": {detail}" if detail else "")
    else:  # a status this module does not know yet: its message's sentence
        rule, sentence = status, STATUS_MESSAGES[status]
    if m["guard"]:
        sentence += m["guard"]
    try:
        cost = float(m["cost"])
    except ValueError:
        cost = None
    return StopRule(rule, sentence, int(m["it"]), cost)


def status_line(status: str, message: str | None, converged: bool | None = None) -> str:
    """``status: WORD (converged after N iterations, cost C) - the rule that fired``; for a message that is
    not an LM message, ``status: WORD - message`` as it is."""
    rule = stop_rule(status, message or "")
    if rule is None:
        return f"status: {status}" + (f" - {message}" if message else "")
    how = {True: "converged", False: "not converged"}.get(converged, "stopped")
    at = f"{how} after {rule.iterations} iteration{'s' if rule.iterations != 1 else ''}"
    if rule.cost is not None:
        at += f", cost {rule.cost:.6g}"
    return f"status: {status} ({at}) - {rule.sentence}"
