"""Progress of sweeps and regime maps (jaxcrank.runs.programs.progress): a bar on a terminal,
plain lines without carriage returns in a log."""

import io

import numpy as np
import pytest

import jaxcrank as jc
from jaxcrank.runs import programs, sweep


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_a_log_gets_a_line_every_tenth_and_at_the_end_without_carriage_returns():
    log = io.StringIO()
    with programs.progress(100, desc="designs", unit="design", stream=log) as bar:
        for _ in range(50):
            bar.update(2)
    text = log.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    # a line when it starts, at 10 %, 20 %, ..., 90 %, and when it ends
    assert len(lines) == 11, lines
    assert lines[0] == "designs: 0/100 designs ..."
    assert [line.split(" (")[1].split(" %")[0] for line in lines[1:-1]] == [str(k) for k in range(10, 100, 10)]
    assert lines[-1].startswith("designs: done, 100/100 designs in ")


def test_a_resumed_run_counts_from_where_it_stopped_and_a_failure_says_so():
    log = io.StringIO()
    with pytest.raises(RuntimeError):
        with programs.progress(10, initial=4, desc="designs", unit="design", stream=log) as bar:
            bar.update(1)  # 5 of 10
            raise RuntimeError
    lines = log.getvalue().splitlines()
    assert lines[0] == "designs: 4/10 designs ..."
    assert lines[1].startswith("designs: 5/10 designs (50 %)")
    assert lines[-1].startswith("designs: failed, 5/10 designs in ")


def test_a_terminal_keeps_the_bar_and_disable_shows_nothing():
    tty = _Terminal()
    with programs.progress(4, desc="designs", unit="design", stream=tty) as bar:
        bar.update(4)
    assert "\r" in tty.getvalue() and "4/4" in tty.getvalue()
    quiet = io.StringIO()
    with programs.progress(4, desc="designs", stream=quiet, disable=True) as bar:
        bar.update(4)
    assert quiet.getvalue() == ""


def test_a_sweep_logs_plain_lines_when_stderr_is_not_a_terminal(capsys):
    """Two designs of 1 ms of the paper run, standard error captured (not a terminal)."""
    settings = sweep.Settings(revolutions=0.01, samples_per_revolution=360, metrics_from_revolution=0.0)
    table = sweep.run(jc.paper(), ["clearance_C"], [[2e-4], [3e-4]], settings, chunk=1, engine="xla")
    assert list(table["status"]) == ["ok", "ok"] and np.all(table["steps"] > 0)
    err = capsys.readouterr().err
    assert "\r" not in err
    assert "designs: 0/2 designs ..." in err and "designs: done, 2/2 designs in " in err


def test_a_regime_map_logs_plain_lines_when_stderr_is_not_a_terminal(capsys):
    """Three designs of the paper run, settled for one revolution, standard error captured."""
    from jaxcrank.runs import regimes

    mech = jc.paper()
    xs = [[float(mech.rod_length)], [1.01 * float(mech.rod_length)], [1.02 * float(mech.rod_length)]]
    table = regimes.classify(mech, ["rod_length"], xs, settle_revolutions=1, max_period=1, chunk=1)
    assert list(table["status"]) == ["ok"] * 3
    err = capsys.readouterr().err
    assert "\r" not in err
    lines = [line for line in err.splitlines() if line.startswith("designs: ")]
    # a line when it starts, one per design (each a third of the work), one when it ends
    assert lines[0] == "designs: 0/3 designs ..." and lines[-1].startswith("designs: done, 3/3 designs in ")
    assert [line.split(" (")[1].split(" %")[0] for line in lines[1:-1]] == ["33", "67"]
