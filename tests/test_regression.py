"""Regression: every method and sensor on every sample log against committed metrics.

Tolerance: 1 mm plus 0.5 % of the expected value. Deterministic code on seeded logs gives the same
numbers on any machine to far better than that; anything beyond it is a change in behaviour. A
change that makes an estimate worse fails and says which metric moved and by how much; one that
makes it better fails too, asking for the expected values to be regenerated, so that a later
regression cannot hide under a stale baseline.
"""

from __future__ import annotations

import json

import pytest

from regression.expected import EXPECTED, METRICS, SAMPLES, measure

ABS_TOL_M = 0.001
REL_TOL = 0.005
REGENERATE = "python tests/regression/expected.py"


@pytest.fixture(scope="module")
def measured() -> dict[str, dict[str, dict[str, float]]]:
    return measure()


def test_every_sample_log_has_expected_values() -> None:
    expected = json.loads(EXPECTED.read_text())
    assert sorted(expected) == [p.name for p in SAMPLES], f"run {REGENERATE}"


@pytest.mark.parametrize("log", [p.name for p in SAMPLES])
def test_metrics_have_not_moved(log: str, measured: dict[str, dict[str, dict[str, float]]]) -> None:
    expected = json.loads(EXPECTED.read_text())[log]
    now = measured[log]
    assert sorted(now) == sorted(expected), f"estimates changed: {sorted(now)}; run {REGENERATE}"
    worse, better = [], []
    for name, metrics in expected.items():
        for metric in METRICS:
            old, new = metrics[metric], now[name][metric]
            if old is None or new is None:
                assert old == new, f"{log} {name} {metric}: {old} -> {new}"
                continue
            if abs(new - old) <= ABS_TOL_M + REL_TOL * abs(old):
                continue
            line = f"{log} {name} {metric}: {old:.4f} -> {new:.4f} m ({new - old:+.4f} m)"
            # for the bias, worse means further from zero
            (worse if abs(new) > abs(old) else better).append(line)
    assert not worse, "worse:\n" + "\n".join(worse)
    assert not better, f"better (regenerate with `{REGENERATE}`):\n" + "\n".join(better)
