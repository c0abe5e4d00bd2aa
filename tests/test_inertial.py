"""The accelerometer's health as the provenance records it
(:func:`altfuse.inertial.vibration_record`)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from altfuse.cli import cli
from altfuse.inertial import VIBE_ACCEPTABLE_M_S2, VIBE_PROBLEM_M_S2, vibration_record
from altfuse.model import Vibration
from conftest import shared_log


def test_the_vibration_record_counts_time_over_the_bounds_and_only_the_clip_counts_rises() -> None:
    t = np.arange(20) * 0.1  # VIBE at 10 Hz
    level = np.full((20, 3), 5.0)
    level[4:9, 2] = VIBE_ACCEPTABLE_M_S2 + 1.0  # 0.5 s above the first bound, on one axis
    level[6:8, 0] = VIBE_PROBLEM_M_S2 + 5.0  # 0.2 s of them above the second
    # cumulative: 3 clips at 0.5 s, 2 at 0.9 s, a reboot's reset to 0, 4 more at 1.5 s
    clips = np.array([0] * 5 + [3] * 4 + [5] * 3 + [0] * 3 + [4] * 5, dtype=float)
    record = vibration_record(Vibration("VIBE[0].Clip0", t, level, clips))
    assert record["max_level_m_s2"] == VIBE_PROBLEM_M_S2 + 5.0
    assert record["above_acceptable_s"] == pytest.approx(0.5)
    assert record["above_problem_s"] == pytest.approx(0.2)
    assert record["clipped_samples"] == 3 + 2 + 4  # the reset's drop is no clip
    assert record["clipped_at_s"] == [0.5, 0.9, 1.5]


def test_a_pause_of_the_log_after_a_loud_sample_is_no_time_above_the_bounds() -> None:
    t = np.array([0.0, 0.1, 0.2, 60.2, 60.3])  # the log paused for a minute after 0.2 s
    level = np.full((5, 3), 5.0)
    level[2] = VIBE_PROBLEM_M_S2 + 1.0
    record = vibration_record(Vibration("VIBE[0].Clip0", t, level, np.zeros(5)))
    assert record["above_problem_s"] == pytest.approx(0.2)  # twice its 0.1 s interval at most


def test_a_quiet_accelerometer_has_nothing_to_record_but_its_level() -> None:
    t = np.arange(5) * 0.1
    record = vibration_record(Vibration("VIBE[0].Clip", t, np.full((5, 3), 2.0), np.zeros(5)))
    assert record == {
        "source": "VIBE[0].Clip",
        "max_level_m_s2": 2.0,
        "above_acceptable_s": 0.0,
        "above_problem_s": 0.0,
        "clipped_samples": 0,
        "clipped_at_s": [],
    }


def test_info_tells_a_crash_s_vibration_and_clipping() -> None:
    """A real Copter 3.4 log of a mechanical failure: its VIBE peaks at 69 m/s^2 and its first
    accelerometer clips 28 times within 0.6 s."""
    log = str(shared_log("ardupilot/beastayyg_log_0036_mechanical_failure.bin"))
    text = CliRunner().invoke(cli, ["info", log]).stdout
    assert (
        "vibration: up to 69.0 m/s² (5.1 s above 30, 0.4 s above 60), 28 samples clipped "
        "(first at 373.1 s)"
    ) in text
    health = json.loads(CliRunner().invoke(cli, ["info", log, "--json"]).stdout)["vibration"]
    assert health["clipped_samples"] == 28
    assert health["clipped_at_s"] == [373.076, 373.177, 373.579, 373.679]
