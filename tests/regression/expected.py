"""Expected metrics of every method and sensor on every log in sample_logs/.

Regenerate after a deliberate change (and say in the commit why the numbers moved):

    python tests/regression/expected.py

The tests (tests/test_regression.py) compare a fresh evaluation with expected.json.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from altfuse.evaluation import evaluate

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = sorted((ROOT / "sample_logs").glob("*.bin"))
EXPECTED = Path(__file__).with_name("expected.json")
METRICS = ("rmse", "mae", "max_abs", "bias")


def measure() -> dict[str, dict[str, dict[str, Any]]]:
    """{log: {estimate: {metric: value}}} for every sample log."""
    out: dict[str, dict[str, dict[str, Any]]] = {}
    for log in SAMPLES:
        result = evaluate(log)
        out[log.name] = {
            row.name: {m: row.overall.as_dict()[m] for m in METRICS} for row in result.rows
        }
    return out


def main() -> None:
    EXPECTED.write_text(json.dumps(measure(), indent=2, sort_keys=True) + "\n")
    sys.stdout.write(f"wrote {EXPECTED}\n")


if __name__ == "__main__":
    main()
