"""Figures of a simulation run (jaxcrank.runs.plots): the start-up impact does not set the scale."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import jaxcrank as jc  # noqa: E402
from jaxcrank.runs import plots  # noqa: E402


def _columns():
    """Two revolutions at 600 rpm: a steady sine force and a 50x start-up spike in the first."""
    t = np.linspace(0.0, 0.2, 2001)
    f = 1000.0 * (1.0 + np.sin(2 * np.pi * 10 * t))
    f[20] = 50_000.0
    return {"t": t, "crank_angle": 3600.0 * t, "force_C_normal": f, "force_B_normal": 0.5 * f}


def _panels(fig):
    """The figure's panels by the joint their title names."""
    return {ax.get_title(loc="left").split("joint ")[1].split(" ")[0]: ax for ax in fig.axes}


def _covered(ax, note) -> int:
    """How many of ``ax``'s line points lie inside the box of ``note`` (the figure drawn)."""
    fig = ax.figure
    fig.canvas.draw()
    box = note.get_bbox_patch().get_window_extent(fig.canvas.get_renderer())
    n = 0
    for line in ax.get_lines():
        p = ax.transData.transform(np.column_stack(line.get_data()))
        n += int(np.sum((p[:, 0] >= box.x0) & (p[:, 0] <= box.x1) & (p[:, 1] >= box.y0) & (p[:, 1] <= box.y1)))
    return n


def test_contact_force_figure_shows_each_joint_scaled_after_the_start_up():
    with plots.style():
        fig = plots._contact_forces(_columns(), jc.paper())
    panels = _panels(fig)
    assert sorted(panels) == ["B", "C"] and len(fig.axes) == 2
    top = panels["C"]
    # one curve per panel: joint C's panel draws C alone, against the crank's angle (0..720 deg)
    assert len(top.lines) == 1 and np.array_equal(top.lines[0].get_ydata(), _columns()["force_C_normal"])
    np.testing.assert_allclose(top.lines[0].get_xdata(), 3600.0 * _columns()["t"], rtol=0, atol=1e-9)
    lo, hi = top.get_ylim()
    # the steady range 0..2000 N with a margin, and at most a band for the note on top
    assert 2000.0 < hi < 1.5 * 2000.0 and lo > -0.2 * 2000.0
    notes = [c.get_text() for c in top.texts]
    assert len(notes) == 1 and "50,000 N" in notes[0] and "off scale" in notes[0] and "at 7°" in notes[0]
    assert "summary.json" not in top.get_title(loc="left")  # titles say what is drawn
    # the note covers no sample of the curve
    assert _covered(top, top.texts[0]) == 0
    plt.close(fig)


@pytest.mark.parametrize("n", [500, 1001])
def test_a_run_within_one_revolution_is_drawn_whole(n):
    """Half a revolution (0.05 s), and exactly one (0.1 s: a steady-state orbit's): no
    start-up shaded, the scale set by every sample."""
    cols = {k: v[:n] for k, v in _columns().items()}
    fig = plots._contact_forces(cols, jc.paper())
    c = _panels(fig)["C"]
    assert c.get_ylim()[1] >= 50_000.0 and not c.texts and not c.patches
    plt.close(fig)


def test_an_orbit_of_two_revolutions_is_drawn_whole():
    """A periodic orbit (``from_rest=False``, as `jaxcrank steady` draws it) has no start-up:
    two revolutions, nothing shaded, the scale set by every sample."""
    cols = _columns()
    steady = np.ones(len(cols["t"]), dtype=bool)
    fig = plots._contact_forces(cols, jc.paper(), steady=steady)
    c = _panels(fig)["C"]
    assert c.get_ylim()[1] >= 50_000.0 and not c.texts and not c.patches
    plt.close(fig)


def test_history_marks_the_reported_best_iterate(tmp_path, monkeypatch):
    from optim import plots as optim_plots

    history = [{"iteration": i, "objective_deg": f} for i, f in enumerate([0.3, 0.1, 0.2, 0.15])]
    drawn = {}
    monkeypatch.setattr(optim_plots.plt, "close", lambda fig: drawn.setdefault("fig", fig))
    optim_plots.plot_history(history, tmp_path / "history.png", best=0.1)
    assert (tmp_path / "history.png").exists()
    star = [ln for ln in drawn["fig"].axes[0].lines if ln.get_marker() == "*"]
    assert len(star) == 1 and list(star[0].get_xdata()) == [1] and list(star[0].get_ydata()) == [0.1]
    assert "iteration 1" in star[0].get_label()


def test_figures_are_named_from_the_description():
    """The paper's figures and a four-bar's: one per reported deviation, the output
    link's acceleration, contact forces, driving moment, pins, transmission angle and
    bearing loads; the time series against the crank's angle by default, or time."""
    from jaxcrank import outputs

    expected = {
        "paper": {"rod_x", "slider_x", "slider_acceleration"},
        "four-bar": {"rocker_angle", "rocker_acceleration"},
    }
    common = {"contact_force", "driving_moment", "pin_trajectories", "transmission_angle", "bearing_loads"}
    series = {"contact_force", "driving_moment", "transmission_angle"}
    for name, names in expected.items():
        mech = jc.preset(name)
        cols = outputs.trajectory(jc.simulate(mech, 2e-3, n_samples=21))
        for against, label in (("angle", "crank angle from the start [deg]"), ("time", "t [s]")):
            figs = plots.figures(cols, mech, against=against)
            assert set(figs) == {f"{n}.png" for n in names | common}, name
            for key in series | names:
                labels = {ax.get_xlabel() for ax in figs[f"{key}.png"].axes} - {""}
                assert labels == {label}, (name, key, labels)
            x = figs["driving_moment.png"].axes[0].lines[0].get_xdata()
            expected_x = cols["crank_angle"] - cols["crank_angle"][0] if against == "angle" else cols["t"]
            np.testing.assert_allclose(x, expected_x, rtol=0, atol=1e-12)
            for fig in figs.values():
                plt.close(fig)


def test_against_anything_else_is_refused():
    cols = _columns()
    for wrong in ("Angle", "crank", None):
        with pytest.raises(ValueError, match=r"against = .*'angle'.*'time'"):
            plots.figures(cols, jc.paper(), against=wrong)


def test_angle_ticks_every_90_deg_on_a_wide_panel_every_360_on_a_long_run():
    with plots.style():
        fig = plots._contact_forces(_columns(), jc.paper())  # 720 deg on an 8 in wide panel
        ticks = fig.axes[-1].get_xticks()
        assert set(np.arange(0.0, 721.0, 90.0)) <= set(ticks) and np.all(np.diff(ticks) == 90.0)
        plt.close(fig)
        long = {k: np.concatenate([v, v[1:]]) for k, v in _columns().items()}
        long["t"] = np.linspace(0.0, 0.4, len(long["t"]))
        long["crank_angle"] = 3600.0 * long["t"]  # four revolutions
        fig = plots._contact_forces(long, jc.paper())
        major = fig.axes[-1].get_xticks()
        assert np.all(np.diff(major) == 360.0)
        every = np.sort(np.concatenate([major, fig.axes[-1].xaxis.get_minorticklocs()]))
        assert set(np.arange(0.0, 1441.0, 90.0)) <= set(every)
        plt.close(fig)


def _loads_columns():
    """The paper's joints with constant pin-side forces: A (-30, 40) N, B (-100, 0) N with
    the rod at 90 deg, C (0, 2000) N, the guide (0, 50) N; the slider moving 0.3 m."""
    t = np.linspace(0.0, 0.2, 401)
    cols = {"t": t, "crank_angle": 3600.0 * t, "rod_angle": np.full_like(t, 90.0)}
    cols.update(slider_x=0.25 + 0.15 * (1 - np.cos(2 * np.pi * 10 * t)), slider_y=np.full_like(t, 0.05))
    cols["slider_angle"] = np.zeros_like(t)
    for joint, (fx, fy) in {"A": (-30.0, 40.0), "B": (-100.0, 0.0), "C": (0.0, 2000.0), "guide": (0.0, 50.0)}.items():
        cols[f"force_{joint}_x"], cols[f"force_{joint}_y"] = np.full_like(t, fx), np.full_like(t, fy)
    return cols


def test_bearing_loads_are_the_force_on_the_hole_in_its_bodys_frame():
    """A: in the ground, minus the pin's force (30, -40) N: 50 N at 306.87 deg; B: minus
    (-100, 0) N in the rod's frame turned by 90 deg: 100 N at 270 deg; C: 2 kN (in kN),
    minus (0, 2000) N in the rod's frame: at 180 deg; the
    guide: -50 N normal to it along the slider's 300 mm of travel; samples after the
    first revolution only."""
    from jaxcrank.runs import plots_loads

    cols = _loads_columns()
    steady = cols["crank_angle"] >= 360.0
    with plots.style():
        fig = plots_loads.bearing_loads(cols, jc.paper(), steady)
    panels = {ax.get_title().split(":")[0]: ax for ax in fig.axes}
    assert sorted(panels) == ["A", "B", "C", "guide"]
    for joint, (r, deg) in {"A": (50.0, np.degrees(np.arctan2(-40.0, 30.0)) % 360), "B": (100.0, 270.0)}.items():
        phi, radius = (np.asarray(v) for v in panels[joint].lines[0].get_data())
        assert len(radius) == int(steady.sum())
        np.testing.assert_allclose(radius, r, rtol=1e-12)
        np.testing.assert_allclose(np.degrees(phi) % 360.0, deg, rtol=0, atol=1e-9)
        assert f"peak {r:.0f} N at {deg:.0f}°" in panels[joint].get_title(), panels[joint].get_title()
    c = panels["C"]
    np.testing.assert_allclose(c.lines[0].get_ydata(), 2.0, rtol=1e-12)  # kN
    assert "[kN]" in c.get_title() and "peak 2 kN at 180°" in c.get_title()
    g = panels["guide"]
    s, normal = (np.asarray(v) for v in g.lines[0].get_data())
    np.testing.assert_allclose(normal, -50.0, rtol=1e-12)
    assert np.ptp(s) == pytest.approx(np.ptp(cols["slider_x"][steady]) * 1e3, rel=1e-12)
    assert g.get_xlabel().endswith("[mm]") and "[N]" in g.get_ylabel()
    plt.close(fig)


def test_poincare_section_points_are_drawn_over_an_open_star_with_a_revolution_colour_bar(tmp_path, monkeypatch):
    """``jaxcrank steady``'s Poincare plot from the states of a 10 ms paper run standing in
    for six section points (periodic, y* the last): every point is drawn, above the star,
    which is unfilled; one colour bar spans revolutions 0 to 5; the figure is saved."""
    import types

    from jaxcrank.numerics import shooting
    from jaxcrank.runs import steady_cli

    mech = jc.paper()
    ys = np.asarray(jc.simulate(mech, 0.01, n_samples=6).ys)
    m = shooting.dynamic_size(mech)
    steady = types.SimpleNamespace(mechanism=mech, section_points=ys, section_state=ys[-1], monodromy=np.eye(m),
                                   regime="periodic", period_revolutions=1)  # fmt: skip
    drawn = {}
    monkeypatch.setattr(plt, "close", lambda fig: drawn.setdefault("fig", fig))
    assert steady_cli.poincare_plot(steady, tmp_path / "poincare.png").stat().st_size > 0
    fig = drawn["fig"]
    joints = [ax for ax in fig.axes if ax.get_title(loc="left").startswith("joint ")]
    assert [ax.get_title(loc="left") for ax in joints] == ["joint B", "joint C"]
    for ax in joints:
        (points,) = ax.collections[:1]
        star = next(line for line in ax.lines if line.get_marker() == "*")
        assert len(points.get_offsets()) == 6 and points.get_zorder() > star.get_zorder()
        assert star.get_markerfacecolor() == "none"
    (bar,) = [ax for ax in fig.axes if ax.get_ylabel() == "revolution of the settle"]
    assert bar.get_ylim() == (-0.5, 5.5)
    assert {0.0, 5.0} <= set(bar.get_yticks())
    plt.close(fig)
