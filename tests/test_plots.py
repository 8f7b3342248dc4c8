"""Figures of a simulation run (jaxcrank.runs.plots): the start-up impact does not set the scale."""

import matplotlib

matplotlib.use("Agg")

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

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
    return {ax.get_title().split("joint ")[1].split(" ")[0]: ax for ax in fig.axes}


def test_contact_force_figure_shows_each_joint_scaled_after_the_start_up():
    fig = plots._contact_forces(_columns(), jc.paper())
    panels = _panels(fig)
    assert sorted(panels) == ["B", "C"] and len(fig.axes) == 2
    top = panels["C"]
    # one curve per panel: joint C's panel draws C alone
    assert len(top.lines) == 1 and np.array_equal(top.lines[0].get_ydata(), _columns()["force_C_normal"])
    lo, hi = top.get_ylim()
    assert hi < 2100.0 * 1.1 and lo > -0.2 * 2000.0  # the steady range 0..2000 N with a margin
    notes = [c.get_text() for c in top.texts]
    assert len(notes) == 1 and "50,000 N" in notes[0] and "off scale" in notes[0]
    plt.close(fig)


def test_a_run_within_one_revolution_is_drawn_whole():
    cols = {k: v[:500] for k, v in _columns().items()}  # 0.05 s: half a revolution
    fig = plots._contact_forces(cols, jc.paper())
    c = _panels(fig)["C"]
    assert c.get_ylim()[1] >= 50_000.0 and not c.texts
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
    link's acceleration, contact forces, driving moment, pins, transmission angle."""
    from jaxcrank import outputs

    expected = {
        "paper": {"rod_x", "slider_x", "slider_acceleration"},
        "four-bar": {"rocker_angle", "rocker_acceleration"},
    }
    common = {"contact_force", "driving_moment", "pin_trajectories", "transmission_angle"}
    for name, names in expected.items():
        mech = jc.preset(name)
        cols = outputs.trajectory(jc.simulate(mech, 2e-3, n_samples=21))
        figs = plots.figures(cols, mech)
        assert set(figs) == {f"{n}.png" for n in names | common}, name
        for fig in figs.values():
            plt.close(fig)
