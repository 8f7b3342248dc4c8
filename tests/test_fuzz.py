"""Property-based tests (hypothesis): drawn valid designs solve to finite, energy-
consistent outputs inside the geometric bounds or report a named failure; sweep tables
are complete with empty cells for failed designs; drawn bad inputs (NaN, inf, negative,
zero, wrong types, unknown keys, in TOML files, dicts and ``--set``) raise a
ParameterError naming the parameter.

Examples are derandomized or seeded (the same draw every run). The default suite draws a few
designs of one structure (one compiled solve); the ``slow`` test draws 10 designs of
each of the 18 structures (180), and ``bench/fuzz_report.py`` tabulates that draw in
docs/reliability.md."""

from __future__ import annotations

import csv
import json
import math
import os
import tempfile
import zlib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, example, given, seed, settings
from hypothesis import strategies as st

import jaxcrank as jc
from jaxcrank import cli, config
from jaxcrank.physics.params import ParameterError

from . import fuzz


def quick(max_examples):
    """Derandomized (the same draw every run), no example database, no deadline (the
    first example compiles)."""
    return settings(
        max_examples=max_examples,
        deadline=None,
        database=None,
        derandomize=True,
        suppress_health_check=list(HealthCheck),
    )


def _record(mech, res):
    """Append the draw and its outcome to $JAXCRANK_FUZZ_RECORD (bench/fuzz_report.py)."""
    path = os.environ.get("JAXCRANK_FUZZ_RECORD")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps({**fuzz.describe(mech), **res}) + "\n")


# ------------------------------------------------------------------ valid designs


# found by this test: unequal clearances (10 um at B, 1 um at C) put the rod centre 1.1 %
# outside the bound deviation_bounds gave before it used rho_B instead of play / 2
_PIN = dict(contact=jc.Contact(law=jc.laws.Hybrid(), restitution=1.0), friction=jc.Friction(coefficient=0.0))
UNEQUAL_CLEARANCES = jc.SliderCrank(
    crank_length=0.28125,
    rod_length=0.5625,
    offset=0.0,
    crank_mass=1.0,
    rod_mass=1.0,
    slider_mass=1.0,
    rod_inertia=0.1,
    driver=jc.ConstantSpeed(body="crank", speed=2.0 * math.pi * 100.0 / 60.0, initial_angle=1.0),
    joints={
        "A": jc.Ideal(),
        "B": jc.Clearance(hole_radius=0.015625, pin_radius=0.015615, **_PIN),
        "C": jc.Clearance(hole_radius=0.015625, pin_radius=0.015624, **_PIN),
        "guide": jc.Ideal(),
    },
)


@quick(12)
@given(fuzz.designs(structures=[("hybrid", "BC")]))
@example(UNEQUAL_CLEARANCES)
def test_drawn_designs_solve_or_report_a_named_failure(mech):
    res = fuzz.outcome(mech)
    fuzz.assert_outcome(res)


@pytest.mark.long
@pytest.mark.slow
@pytest.mark.parametrize("law, layout", fuzz.STRUCTURES, ids=[f"{a}-{b}" for a, b in fuzz.STRUCTURES])
def test_drawn_designs_of_every_structure(law, layout):
    """10 designs for each of the 6 laws x 3 joint layouts: 180 designs. Each structure
    has its own fixed seed (derandomized draws would repeat the same 10 numbers in
    every structure)."""

    @seed(zlib.crc32(f"{law}-{layout}".encode()))
    @settings(max_examples=10, deadline=None, database=None, suppress_health_check=list(HealthCheck))
    @given(fuzz.designs(structures=[(law, layout)]))
    def check(mech):
        res = fuzz.outcome(mech)
        _record(mech, res)
        fuzz.assert_outcome(res)

    check()


# ------------------------------------------------------------------ sweep tables

SWEEP_NAMES = ["clearance_C", "driver.speed", "contact.restitution", "memory.memory_time"]


def _sweep_settings():
    """0.01 revolution (3.6 deg): 0.2..2 ms at 300..3000 rpm, the first impacts."""
    from jaxcrank import sweep

    return sweep.Settings(
        revolutions=0.01,
        samples_per_revolution=1000,
        metrics_from_revolution=0.0,
        options=jc.DEFAULTS.replace(max_steps=5000),
    )


@st.composite
def sweep_designs(draw):
    """1..5 designs; some invalid (clearance beyond the 8 mm hole, negative speed,
    restitution above 1) and some too stiff for the step budget (a 1e-10 s memory)."""
    rows = []
    for _ in range(draw(st.integers(1, 5))):
        rows.append(
            [
                draw(st.one_of(st.floats(1e-6, 1e-3), st.just(9e-3))),
                draw(st.one_of(st.floats(2 * math.pi * 5.0, 2 * math.pi * 50.0), st.just(-10.0))),
                draw(st.one_of(st.floats(0.3, 1.0), st.just(1.5))),
                draw(st.sampled_from([1e-5, 1e-10])),
            ]
        )
    return np.array(rows)


@quick(6)
@given(sweep_designs())
def test_sweep_table_rows_are_complete_and_failed_cells_empty(designs):
    from jaxcrank import sweep

    base = jc.paper()
    with tempfile.TemporaryDirectory() as tmp:
        tab = sweep.run(base, SWEEP_NAMES, designs, _sweep_settings(), out=tmp, chunk=1, progress=False, engine="xla")
        with open(Path(tmp) / "table.csv", newline="") as f:
            raw = list(csv.reader(f))
    cols = sweep.columns(base, SWEEP_NAMES)
    metric_names = sweep.metric_names(base)
    assert raw[0] == cols
    assert len(raw) == 1 + len(designs)
    assert sorted(int(r[0]) for r in raw[1:]) == list(range(len(designs)))
    metric_at = [cols.index(k) for k in metric_names]
    for r in raw[1:]:
        assert len(r) == len(cols), r
        i, status = int(r[0]), r[cols.index("status")]
        assert status in sweep.STATUSES
        assert [float(v) for v in r[1 : 1 + len(SWEEP_NAMES)]] == list(designs[i])  # exact round trip
        cells = [r[j] for j in metric_at]
        if status == "ok":
            assert all(c != "" and math.isfinite(float(c)) for c in cells), r
            assert r[cols.index("message")] == ""
        else:
            assert cells == [""] * len(cells), r  # empty, not "nan"
            assert r[cols.index("message")], r
        if status == "invalid":
            assert r[cols.index("steps")] == ""
        else:
            assert int(r[cols.index("steps")]) >= 0
    # the returned table is the file's
    assert list(tab["index"]) == list(range(len(designs)))
    ok = tab["status"] == "ok"
    for k in metric_names:
        assert np.all(np.isfinite(tab[k][ok])) and np.all(np.isnan(tab[k][~ok]))
    # the drawn invalid designs are the ones reported invalid
    invalid = (designs[:, 0] >= 8e-3) | (designs[:, 1] <= 0) | (designs[:, 2] > 1)
    np.testing.assert_array_equal(tab["status"] == "invalid", invalid)


# ------------------------------------------------------------------ bad inputs

# documented lower bounds, by a parameter's last name: (lower, lower included); None: no lower bound
_LOWER = {
    "crank_length": (0.0, False),
    "rod_length": (0.0, False),
    "offset": None,
    "crank_mass": (0.0, False),
    "rod_mass": (0.0, False),
    "slider_mass": (0.0, False),
    "crank_inertia": (0.0, False),
    "rod_inertia": (0.0, False),
    "slider_inertia": (0.0, False),
    "speed": (0.0, False),
    "initial_angle": None,
    "gravity": (0.0, True),
    "hole_radius": (0.0, False),
    "pin_radius": (0.0, False),
    "youngs_modulus": (0.0, False),
    "poisson_ratio": (0.0, False),
    "restitution": (0.0, False),
    "exponent": (1.0, True),
    "min_approach_speed": (0.0, False),
    "memory_time": (0.0, False),
    "freeze_time": (0.0, False),
    "reset_window": (0.0, False),
    "reset_time": (0.0, False),
    "v_ref": (0.0, False),
    "tau": (0.0, False),
    "t_dwell": (0.0, False),
    "gate_width": (0.0, False),
    "coefficient": (0.0, True),
    "stick_speed": (0.0, True),
    "slip_speed": (0.0, False),
}


def _numbers(table: dict, prefix: str = "") -> list[str]:
    """Dotted paths of the numbers in a nested dict of [`config.to_dict`][jaxcrank.runs.config.to_dict]."""
    out = []
    for k, v in table.items():
        if isinstance(v, dict):
            out += _numbers(v, f"{prefix}{k}.")
        elif isinstance(v, float):
            out.append(f"{prefix}{k}")
    return out


def _tables(table: dict, prefix: str = "") -> list[str]:
    """Dotted paths of the tables in a nested dict."""
    out = []
    for k, v in table.items():
        if isinstance(v, dict):
            out += [f"{prefix}{k}", *_tables(v, f"{prefix}{k}.")]
    return out


#: every numeric parameter of the paper preset as a file names it (``joints.B.contact.restitution``)
NUMERIC = _numbers(config.to_dict(jc.paper()))
assert set(p.rsplit(".", 1)[-1] for p in NUMERIC) == set(_LOWER), "a parameter without a documented lower bound"


def _message_name(path: str) -> str:
    """The word an error about ``path`` must contain: the parameter's own name (the
    table's name is checked separately where it is needed)."""
    return path.rsplit(".", 1)[-1]


@st.composite
def bad_values(draw):
    """(dotted parameter path, a value outside its documented range or of a wrong type)."""
    path = draw(st.sampled_from(NUMERIC))
    low = _LOWER[path.rsplit(".", 1)[-1]]
    kinds = [
        st.just(math.nan),
        st.just(math.inf),
        st.just(-math.inf),
        st.text(max_size=5),
        st.booleans(),
        st.lists(st.floats(0, 1), max_size=2),
    ]
    if low is not None:
        lo, closed = low
        kinds.append(st.floats(-1e6, lo, exclude_max=closed).filter(lambda v: v < lo or not closed))
        if not (lo < 0.0 or (lo == 0.0 and closed)):
            kinds.append(st.just(0.0))
    return path, draw(st.one_of(kinds))


def _nest(path, value):
    out = value
    for part in reversed(path.split(".")):
        out = {part: out}
    return out


@quick(150)
@given(bad_values())
def test_drawn_bad_values_raise_a_named_error(case):
    path, value = case
    with pytest.raises(ParameterError) as err:
        config.from_dict(_nest(path, value))
    msg = str(err.value)
    assert _message_name(path) in msg, (path, value, msg)
    if "." in path:
        assert path.split(".")[0] in msg, (path, value, msg)  # which table


_IDENT = st.from_regex(r"[a-z][a-z_]{0,11}", fullmatch=True)


@st.composite
def unknown_keys(draw):
    """A dotted key that is not a parameter: at the top level or inside a table (a joint,
    its laws and materials, the driver)."""
    plain = config.to_dict(jc.paper())
    if draw(st.booleans()):
        return draw(
            _IDENT.filter(
                lambda k: (
                    k not in plain
                    and not k.startswith("clearance_")
                    and k not in ("contact", "friction", "memory", "mechanism")
                )
            )
        )
    table = draw(st.sampled_from(_tables(plain)))
    valid = plain
    for part in table.split("."):
        valid = valid[part]
    return f"{table}.{draw(_IDENT.filter(lambda k: k not in valid))}"


@quick(60)
@given(st.one_of(bad_values(), unknown_keys().map(lambda k: (k, 1.0))))
def test_drawn_bad_toml_raises_a_named_error(case):
    path, value = case
    try:
        text = tomli_w.dumps({"mechanism": "slider-crank", **_nest(path, value)})
    except (TypeError, ValueError):  # a value TOML cannot hold (e.g. a list of mixed types)
        return
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / "bad.toml"
        f.write_text(text)
        with pytest.raises(ParameterError) as err:
            config.load(f)
    msg = str(err.value)
    assert str(f) in msg and _message_name(path) in msg, (path, value, msg)


_LITERALS = {
    "nan": math.nan,
    "inf": math.inf,
    "-inf": -math.inf,
    "true": True,
    "'x'": "x",
    "[1, 2]": [1, 2],
    "abc": "abc",
    "{a = 1}": {"a": 1},
}


@st.composite
def bad_overrides(draw):
    """``key=value`` text with a bad value (a TOML literal or bare word) or an unknown key."""
    if draw(st.booleans()):
        return draw(unknown_keys()) + "=1"
    path, value = draw(bad_values())
    if isinstance(value, float) and math.isfinite(value):
        text = repr(value)
    else:
        text = draw(st.sampled_from(list(_LITERALS)))
    return f"{path}={text}"


@quick(60)
@given(bad_overrides())
def test_drawn_bad_set_raises_a_named_error(text):
    path = text.split("=", 1)[0]
    with pytest.raises(ParameterError) as err:
        config.apply_overrides(jc.paper(), [text])
    assert _message_name(path) in str(err.value), (text, str(err.value))


@quick(15)
@given(bad_overrides())
def test_drawn_bad_set_on_the_command_line_is_one_named_line(text):
    import contextlib
    import io

    path = text.split("=", 1)[0]
    err = io.StringIO()
    with tempfile.TemporaryDirectory() as tmp, contextlib.redirect_stderr(err):
        rc = cli.main(["simulate", "--out", str(Path(tmp) / "run"), "--quiet", "--no-figures", "--set", text])
    assert rc == 2
    lines = err.getvalue().strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("jaxcrank: error:") and _message_name(path) in lines[0], lines


def _bad_specs():
    from jaxcrank import spec as sweep_spec
    from jaxcrank import sweep

    settings = {f.name for f in sweep.dataclasses.fields(sweep.Settings)} | set(sweep.SOLVE_KEYS)
    return st.one_of(
        _IDENT.filter(lambda k: k not in sweep_spec._SPEC_KEYS).map(lambda k: ({k: 1}, k)),
        _IDENT.filter(lambda k: k not in settings).map(lambda k: ({"simulation": {k: 1}}, k)),
        st.sampled_from(
            ["revolutions", "samples_per_revolution", "metrics_from_revolution", "rtol", "atol", "max_steps"]
        ).flatmap(
            lambda k: st.sampled_from(
                [-1, math.nan, math.inf, "4", True, [1]] + ([] if k == "metrics_from_revolution" else [0])
            ).map(lambda v: ({"simulation": {k: v}}, k))
        ),
    )


@quick(30)
@given(st.deferred(_bad_specs))
def test_drawn_bad_sweep_specs_raise_a_named_error(case):
    from jaxcrank import spec as sweep_spec

    extra, name = case
    spec = {"parameters": {"offset": {"values": [0.0]}}, **extra}
    with pytest.raises(ParameterError) as err:
        sweep_spec.spec_from_dict(spec)
    assert name in str(err.value), str(err.value)
