"""The whole chain on real logs, through the library API."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from altfuse.errors import AltfuseError, UnsupportedLogError
from altfuse.fuse import method
from altfuse.info import damage
from altfuse.io import read_log
from altfuse.job import Outputs, fuse_to_files
from altfuse.pipeline import FuseOptions, fuse_log, fusion_input, prepare_log, run_method
from altfuse.screen import screen
from conftest import SAMPLE_LOG, shared_log


@pytest.mark.parametrize("method", ["support", "mean"])
def test_log_0039_three_sensors_finite_over_the_flight(method: str) -> None:
    run = fuse_log(
        shared_log("ardupilot/beastayyg_log_0039_mechanical_failure.bin"),
        FuseOptions(method=method),
    )
    assert run.referred.names == ("gps", "baro", "rangefinder")
    assert run.provenance["sensors_dropped"] == {}
    assert np.isfinite(run.result.fused).all()
    # 80.5 s to 175.8 s of sensor data at 10 Hz (the GPS's last sample moved 0.11 s earlier by
    # its lag, found against the accelerometer)
    gps = next(s for s in run.provenance["sensors_used"] if s["name"] == "gps")
    assert gps["lag"]["lag_s"] == pytest.approx(0.11, abs=0.01)
    assert run.referred.t.size == 954
    assert run.referred.takeoff_s == pytest.approx(88.2, abs=0.5)
    # a low hop: baro peaks 4.0 m, GPS 2.4 m, rangefinder 2.5 m above take-off; fused 2.41/2.45 m
    assert 2.0 < np.max(run.result.fused) < 3.0


def test_a_copter_whose_barometer_warms_on_the_ground_is_referred_where_it_took_off() -> None:
    """diaven's Copter 4.0 stands 72 s logging while its barometer rises 2.5 m, then hops about
    1 m for 38 s under its rangefinder. The barometer's 1 m rise came at 34.8 s, on the ground:
    the hop read 2.05 m above the rangefinder (2.24 at most). Its land detector said it left
    the ground at 77.5 s (``EV`` NOT_LANDED): the take-off is the rise after that."""
    run = fuse_log(shared_log("ardupilot/diaven_sample01.bin"))
    assert 77.5 < run.referred.takeoff_s < 82.0
    rangefinder = run.referred.h[:, run.referred.names.index("rangefinder")]
    under = np.isfinite(rangefinder)
    gap = run.result.fused[under] - rangefinder[under]
    assert np.median(gap) < 0.6  # 0.49
    assert np.max(np.abs(gap)) < 0.8  # 0.67


def test_the_clock_over_the_overlap_is_fused_from_its_own_samples() -> None:
    """``--span overlap`` refers the sensors over the overlap's clock, and the smoother was
    handed every sample of the log besides: diaven's 72 s on the ground before the overlap (a
    barometer warming 2.5 m, a GPS converging from 23 m) moved the fused height over the
    overlap 0.54 m (median) outside gps2, baro and rangefinder, which agree (0.77 at most).
    A method now gets the samples of its clock's span."""
    log, options = (
        read_log(shared_log("ardupilot/diaven_sample01.bin")),
        FuseOptions(span="overlap"),
    )
    run = fuse_log(log, options)
    inputs = fusion_input(prepare_log(log, options), method("smoother"))
    t, dt = inputs.t, inputs.dt_s
    for s in inputs.samples:
        assert t[0] - dt <= s.t.min()
        assert s.t.max() <= t[-1] + dt
    h, names = run.referred.h, run.referred.names
    agree = h[:, [names.index(n) for n in ("gps2", "baro", "rangefinder")]]
    fused = run.result.fused
    beyond = np.maximum(np.nanmin(agree, axis=1) - fused, fused - np.nanmax(agree, axis=1))
    assert np.median(beyond.clip(0)) < 0.1  # 0.03
    assert beyond.max() < 0.4  # 0.23


@pytest.mark.parametrize(
    ("log", "rate_hz"),
    [
        ("sample", 0.2),  # its GPS dropped: "too few [ticks] beside baro to find its datum"
        ("truth/copter_4.0.0dev_aadimishra_autotest_climb99m.BIN", 0.2),  # refused: GPS too
        ("truth/copter_4.0.4rc2_leaerialtech_hexa_10m.BIN", 0.5),  # 1.4 m off
    ],
)
def test_the_datum_does_not_move_with_the_output_rate(log: str, rate_hz: float) -> None:
    """The datum was found on the output's clock: at 0.2-0.5 Hz a take-off a few seconds into
    the log blurs into a tick or two, and the whole fused height moved by metres (or a sensor
    was dropped, or the log refused); now it is found on a 10 Hz clock whatever the output's
    rate."""
    path = SAMPLE_LOG if log == "sample" else shared_log(log)
    fine = fuse_log(path, FuseOptions(method="mean"))
    coarse = fuse_log(path, FuseOptions(method="mean", rate_hz=rate_hz))
    assert coarse.referred.names == fine.referred.names
    assert coarse.referred.takeoff_s == fine.referred.takeoff_s
    for a, b in zip(coarse.referred.offsets, fine.referred.offsets, strict=True):
        assert a.offset_m == b.offset_m
        assert a.scale == b.scale
    assert coarse.referred.t.size == pytest.approx(fine.referred.t.size * rate_hz / 10.0, abs=1)
    # the coarse clock's ticks referred as the fine clock's are
    step = round(10.0 / rate_hz)
    on_both = np.isin(np.round(fine.referred.t * 10.0), np.round(coarse.referred.t * 10.0))
    assert np.all(np.round(fine.referred.t[on_both] * 10.0) % step == 0)
    heights = np.abs(coarse.referred.h - fine.referred.h[on_both])
    assert np.nanmedian(heights) < 0.3  # a cell's mean against a tick's spline


@pytest.mark.parametrize(
    ("log", "rate_hz"),
    [("sample", 0.5), ("truth/copter_4.5.0dev_skyrats_rfnd_8m.BIN", 0.5), ("sample", 2.0)],
)
def test_a_coarse_clock_s_first_and_last_ticks_are_fused(log: str, rate_hz: float) -> None:
    """At 0.5 Hz the cell of the first tick averages the samples of its second after the log
    begins partway through it, their mean time past the tick, and the tick was written with
    no sensor and no fused height ("none"; 20 of the 33 shared and sample logs that fuse, first
    or last); now each sensor's column runs from its first sample to its last, and the
    smoother's height there is the one at that tick of the 10 Hz run."""
    path = SAMPLE_LOG if log == "sample" else shared_log(log)
    fine = fuse_log(path)
    coarse = fuse_log(path, FuseOptions(rate_hz=rate_hz))
    assert coarse.result.status[[0, -1]].tolist() == ["fused", "fused"]
    on_fine = np.searchsorted(np.round(fine.referred.t, 6), np.round(coarse.referred.t, 6))
    np.testing.assert_allclose(coarse.result.fused, fine.result.fused[on_fine], atol=1e-3)


@pytest.mark.parametrize("rate_hz", [20.0, 50.0])
def test_the_datum_does_not_move_with_a_finer_output_rate(rate_hz: float) -> None:
    """On a clock finer than 10 Hz the datum was found on it: this copter's take-off moved at
    50 Hz, and its offsets and scales by up to 2 cm (0.16 m on a shared log); 21 of 30 logs
    had another take-off at 50 Hz. Now the datum's clock is 10 Hz at every rate."""
    path = shared_log("truth/copter_4.5.0dev_skyrats_rfnd_8m.BIN")
    base = fuse_log(path, FuseOptions(method="mean")).referred
    finer = fuse_log(path, FuseOptions(method="mean", rate_hz=rate_hz)).referred
    assert finer.datum_rate_hz == 10.0
    assert finer.t.size == pytest.approx(base.t.size * rate_hz / 10.0, abs=rate_hz / 10.0)
    assert finer.takeoff_s == base.takeoff_s
    assert [(o.offset_m, o.scale) for o in finer.offsets] == [
        (o.offset_m, o.scale) for o in base.offsets
    ]


def test_ardusub_is_refused() -> None:
    with pytest.raises(UnsupportedLogError, match="ArduSub"):
        fuse_log(shared_log("ardupilot/ardusubtools_small.BIN"))


def test_a_run_without_the_raw_inertial_records_is_the_same() -> None:
    """fuse_to_files lets the log's IMU and attitude go once the method's inputs are made: the
    run is the one made with them."""
    options = FuseOptions(method="smoother")
    prepared = prepare_log(SAMPLE_LOG, options)
    assert prepared.log.imu is not None
    assert prepared.log.attitude is not None
    inputs = fusion_input(prepared, method("smoother"), "smoother")
    lean = prepared.without_inertial()
    assert lean.log.imu is None
    assert lean.log.attitude is None
    assert lean.log.references == prepared.log.references
    ours = run_method(lean, options, inputs).result
    theirs = run_method(prepared, options).result
    np.testing.assert_array_equal(ours.fused, theirs.fused)
    np.testing.assert_array_equal(ours.tick_traces["fused_std"], theirs.tick_traces["fused_std"])


def test_a_fused_run_written_keeps_only_its_sensors_of_the_log(tmp_path: Path) -> None:
    """fuse_to_files lets the log's other samples go before writing (the 300 MB log's peak was
    there): what the commands read afterwards stays (notes, damage, the sensors' counts)."""
    done = fuse_to_files(SAMPLE_LOG, Outputs(csv=tmp_path / "o.csv"))
    log = done.run.log
    full = read_log(SAMPLE_LOG)
    assert full.references
    assert full.imu is not None
    assert log.references == ()
    assert log.imu is None
    assert log.vibration is None
    assert log.temperatures == {}
    assert damage(log) == damage(screen(full))
    assert [s.name for s in log.sensors] == [s.name for s in screen(full).sensors]


def test_the_library_job_never_writes_over_its_log(tmp_path: Path) -> None:
    """``fuse_to_files(log, Outputs(log))`` replaced the log with its own fused table: the
    command line refused it, the library did not. Existing files are replaced unless told not."""
    log = tmp_path / "flight.bin"
    log.write_bytes(SAMPLE_LOG.read_bytes())
    for outputs in (
        Outputs(log),
        Outputs(tmp_path / "o.csv", meta=log),
        Outputs(tmp_path / "o.csv", weights=tmp_path / "o.csv"),
        Outputs(tmp_path / "o.json"),
        Outputs(Path("")),  # the current folder, as "/" is: pathlib's ValueError before
        Outputs(Path("/")),
    ):
        with pytest.raises(AltfuseError):  # ParameterError, or OutputError for the format
            fuse_to_files(log, outputs)
    assert log.read_bytes() == SAMPLE_LOG.read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["flight.bin"]
    old = tmp_path / "o.csv"
    old.write_text("an earlier run\n")
    with pytest.raises(AltfuseError, match=r"o\.csv exists; overwrite=True overwrites it$"):
        fuse_to_files(log, Outputs(old), overwrite=False)
    assert old.read_text() == "an earlier run\n"
    fuse_to_files(log, Outputs(old))
    assert old.read_text().startswith("time_s,")
