"""Each stopping rule of the LM loop (fit.stopping) is a predicate with one status: it fires on its own side of
its threshold, worked out by hand here, and says nothing on the other."""

from __future__ import annotations

import math

import numpy as np
import pytest

from flowchart2sdnn.fit import stopping
from flowchart2sdnn.fit.lm import STATUS_MESSAGES, LMOptions


def test_each_rule_has_one_status_with_a_message():
    fired = [
        stopping.cost_goal(1.0, LMOptions(cost_goal=1.0)),
        stopping.min_grad(np.array([3.0, 4.0]), LMOptions(min_grad=5.5)),
        stopping.max_iter(7, LMOptions(max_iter=7)),
        stopping.mu_max(2e10, LMOptions()),
        stopping.rounding(1, 0.3, 1e-13, 1.0),
        stopping.max_mu_tries(),
        stopping.small_step(True),
        stopping.min_rel_cost_change(1.0, 0.9999, LMOptions(min_rel_cost_change=1e-3)),
        stopping.stall((10.0, 1.001, 1.0008), 1.0005, LMOptions(stall_decrease=0.01, stall_iterations=2)),
        stopping.crawl((10.0, 1.002, 1.001, 1.0), LMOptions(crawl_decrease=0.01, crawl_iterations=2, crawl_cost=1.0)),
    ]
    assert [s.status for s in fired] == ["cost_goal", "min_grad", "max_iter", "mu_max", "small_cost_change",
                                         "max_mu_tries", "small_step", "small_cost_change", "small_cost_change",
                                         "small_cost_change"]
    assert all(s.status in STATUS_MESSAGES for s in fired)


def test_the_gradient_rule_at_its_threshold():
    g = np.array([3.0, 4.0])  # |g| = 5 exactly
    assert stopping.min_grad(g, LMOptions(min_grad=5.0)) is None  # strictly below only
    assert stopping.min_grad(g, LMOptions(min_grad=5.0 + 1e-12)).detail == "|grad| = 5"


def test_the_stall_rule_reads_its_window():
    """Costs 1.10 (two steps back) -> 1.0: the window gained 0.10 of the cost."""
    costs = (5.0, 1.10, 1.05)
    assert stopping.stall(costs, 1.0, LMOptions(stall_decrease=0.1 + 1e-9, stall_iterations=2)) is not None
    assert stopping.stall(costs, 1.0, LMOptions(stall_decrease=0.1 - 1e-9, stall_iterations=2)) is None
    assert stopping.stall(costs[:2], 1.0, LMOptions(stall_decrease=1.0, stall_iterations=2)) is None  # too few


def test_the_crawl_rule_waits_for_the_noise_floor():
    costs = (1.02, 1.01, 1.0)  # 0.02 of the cost over two iterations
    opts = dict(crawl_decrease=0.05, crawl_iterations=2)
    assert stopping.crawl(costs, LMOptions(crawl_cost=0.99, **opts)) is None  # above the floor
    assert stopping.crawl(costs, LMOptions(crawl_cost=1.0, **opts)).detail.startswith(stopping.CRAWL_DETAIL)


def test_mu_max_is_not_the_trust_radius_rule():
    assert stopping.mu_max(1e11, LMOptions(damping="trust")) is None
    assert stopping.mu_max(1e10, LMOptions()) is None  # strictly above


def test_rounding_needs_a_refusal_or_the_gauss_newton_step():
    assert stopping.rounding(0, 0.5, 0.0, 1.0) is None  # the first trial of a damped step is simulated
    assert stopping.rounding(0, 0.0, 0.0, 1.0) is not None
    assert stopping.rounding(1, 0.5, 2e-12, 1.0) is None


@pytest.mark.parametrize("before, after, fires", [(1.0, 0.999, False), (1.0, 0.9999, True), (0.0, 0.0, True)])
def test_the_relative_change_rule(before, after, fires):
    got = stopping.min_rel_cost_change(before, after, LMOptions(min_rel_cost_change=1e-3))
    assert (got is not None) == fires
    if fires and before > 0:
        assert math.isclose(float(got.detail.split()[-1]), 1e-4, rel_tol=1e-2)
