"""Drawings and animations: what is drawn is where the assembly puts it, clearance joints
are marked, the animation's frames follow the run, and the files play."""

import glob
import math
import re
import shutil
import subprocess

import jax.numpy as jnp
import matplotlib
import numpy as np
import pytest
from matplotlib.patches import Circle, Polygon

import jaxcrank as jc
from jaxcrank.physics import closure
from jaxcrank.physics.compiled import compile_model
from jaxcrank.runs import config
from jaxcrank.runs.cli import main
from jaxcrank.views import animation, drawing

matplotlib.use("Agg")

LINKAGES = sorted(glob.glob("docs/linkages/*.toml"))
MECHANISMS = [("preset", n) for n in jc.PRESETS] + [("file", p) for p in LINKAGES]


def _mechanism(kind, name):
    return jc.preset(name) if kind == "preset" else config.load(name)


def _assembly_points(mech, phi):
    """Each joint's hole (guide) and pin (slider) point, m, from the assembly's own frames
    (`jaxcrank assemble`'s path), not from the drawing's geometry."""
    model = compile_model(mech)
    lk = model.linkage
    frames = closure.ideal_frames(lk, model.plan, jnp.asarray(phi), model.signs, model.guesses)
    out = {}
    for j, conn in lk.connections.items():
        pts = []
        for site in conn.sites():
            local = (lk.ground if site.body == "ground" else lk.bodies[site.body].points)[site.point]
            if site.body == "ground":
                pts.append(np.array([float(local.x), float(local.y)]))
            else:
                pts.append(np.asarray(jnp.stack(frames[site.body].point(local.pair())), dtype=float))
        out[j] = pts
    return out


@pytest.mark.parametrize("kind,name", MECHANISMS, ids=[n.split("/")[-1] for _, n in MECHANISMS])
def test_drawn_joints_sit_where_the_assembly_puts_them(kind, name):
    mech = _mechanism(kind, name)
    angle = 37.0  # deg: away from the initial angle and from dead centres
    phi = float(mech.linkage().driver.initial_angle) + math.radians(angle)
    fig = drawing.draw(mech, math.degrees(phi))
    try:
        ax = fig.axes[0]
        drawn = {p.get_gid(): p for p in ax.patches if p.get_gid()}
        expected = _assembly_points(mech, phi)
        lk = mech.linkage()
        assert {g for g in drawn if g.startswith("joint:")} == {f"joint:{j}" for j in lk.connections}
        for j, (hole, pin) in expected.items():
            art = drawn[f"joint:{j}"]
            if lk.connections[j].kind == "revolute":
                assert isinstance(art, Circle)
                at = np.asarray(art.center)
                # the ideal assembly closes the joint: both sides at the drawn centre, to rounding (1e-12 m)
                np.testing.assert_allclose(at, hole, rtol=0, atol=1e-12)
                np.testing.assert_allclose(at, pin, rtol=0, atol=1e-9)
            else:  # the block is centred on the sliding point
                assert isinstance(art, Polygon)
                np.testing.assert_allclose(np.asarray(art.get_xy())[:4].mean(axis=0), pin, rtol=0, atol=1e-12)
            clear = not lk.joints[j].ideal
            assert (f"pin:{j}" in drawn) == (clear and lk.connections[j].kind == "revolute"), j
            if clear:
                assert matplotlib.colors.same_color(art.get_edgecolor(), drawing.CLEARANCE), j
    finally:
        matplotlib.pyplot.close(fig)


def test_a_crank_pins_path_is_the_circle_of_the_crank_length():
    mech = jc.preset("paper")
    fig = drawing.draw(mech)
    try:
        paths = [ln for ln in fig.axes[0].lines if ln.get_linestyle() == ":"]
        radii = [np.hypot(*np.asarray(ln.get_xydata()).T) for ln in paths]
        crank = float(mech.crank_length)
        # the crank pin's path: every point at the crank length from the pivot at the origin (1e-12 m)
        assert any(np.allclose(r, crank, rtol=0, atol=1e-12) for r in radii)
    finally:
        matplotlib.pyplot.close(fig)


def test_draw_refuses_bad_input_by_name(tmp_path, capsys):
    with pytest.raises(jc.ParameterError, match="magnify"):
        drawing.draw(jc.preset("paper"), magnify=0.0)
    assert main(["draw", "--out", str(tmp_path / "x.txt"), "--quiet"]) == 2
    assert ".png, .svg, .pdf" in capsys.readouterr().err
    assert main(["draw", "--mechanism", "four-bar", "--angle", "30", "--out", str(tmp_path / "d.svg")]) == 0
    assert (tmp_path / "d.svg").read_text().lstrip().startswith("<?xml")


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A short run of the paper's mechanism from the command line (0.12 s: a revolution and a fifth)."""
    out = tmp_path_factory.mktemp("run")
    assert main(["simulate", "--t1", "0.12", "--out", str(out), "--no-figures", "--quiet", "--no-cache"]) == 0
    return out


def test_frames_follow_the_last_revolutions_of_the_run(run_dir):
    from jaxcrank.runs import view_cli

    mech, cols = view_cli.read_run(run_dir)
    idx = animation.frame_indices(cols, mech, revolutions=1.0, per_revolution=72)
    angle = cols["crank_angle"][idx]
    # one frame per 5 deg over the last turn, each within a sample (0.1 deg) of its target
    assert len(idx) == 73
    np.testing.assert_allclose(np.diff(angle), 5.0, atol=0.1 + 1e-9)
    assert abs(angle[-1] - cols["crank_angle"][-1]) <= 0.1 + 1e-9
    whole = animation.frame_indices(cols, mech, revolutions=None, per_revolution=72)
    assert whole[0] == 0 and len(whole) == 87  # 1.2 turns at 5 deg a frame, with the first
    with pytest.raises(jc.ParameterError, match="revolutions"):
        animation.frame_indices(cols, mech, revolutions=-1.0)


def test_animate_writes_a_gif_and_an_html_page_that_plays(run_dir, tmp_path, capsys):
    from PIL import Image

    gif, page = tmp_path / "a.gif", tmp_path / "a.html"
    assert main(["animate", str(run_dir), "--out", str(gif), "--frames-per-revolution", "24"]) == 0
    assert main(["animate", str(run_dir), "--out", str(page), "--frames-per-revolution", "24", "--quiet"]) == 0
    with Image.open(gif) as im:
        assert im.n_frames == 25
        im.seek(0)
        first = np.asarray(im.convert("RGB"))
        im.seek(12)
        middle = np.asarray(im.convert("RGB"))
    assert first.shape == middle.shape and (first != middle).any()
    html = page.read_text()
    assert html.count("iVBORw0KGgo") == 25  # 25 PNG frames embedded
    assert not re.search(r"(src|href)=[\"']?(https?:)?//", html) and "start();" in html  # nothing fetched; plays
    assert main(["animate", str(run_dir), "--out", str(tmp_path / "a.webm")]) == 2
    assert ".gif, .mp4, .html" in capsys.readouterr().err
    assert main(["animate", str(tmp_path), "--out", str(gif)]) == 2
    assert "config.toml" in capsys.readouterr().err
    # a steady run's folder: its orbit.csv (the same columns) is animated
    steady = tmp_path / "steady"
    steady.mkdir()
    shutil.copyfile(run_dir / "config.toml", steady / "config.toml")
    shutil.copyfile(run_dir / "trajectory.csv", steady / "orbit.csv")
    assert main(["animate", str(steady), "--frames-per-revolution", "12", "--quiet"]) == 0
    with Image.open(steady / "animation.gif") as im:
        assert im.n_frames == 13


@pytest.mark.skipif(shutil.which("ffmpeg") is None, reason="needs ffmpeg (apt-get install ffmpeg)")
def test_animate_writes_an_mp4_of_every_frame(run_dir, tmp_path):
    out = tmp_path / "a.mp4"
    assert main(["animate", str(run_dir), "--out", str(out), "--frames-per-revolution", "24", "--quiet"]) == 0
    probe = subprocess.run(
        ["ffprobe", "-v", "error", "-count_frames", "-show_entries", "stream=nb_read_frames,codec_name", "-of", "csv",
         str(out)],
        check=True, capture_output=True, text=True,
    ).stdout  # fmt: skip
    assert probe.strip() == "stream,h264,25"


def test_mp4_without_ffmpeg_says_what_to_do(run_dir, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(animation.FFMpegWriter, "isAvailable", classmethod(lambda cls: False))
    assert main(["animate", str(run_dir), "--out", str(tmp_path / "a.mp4")]) == 2
    err = capsys.readouterr().err
    assert "needs ffmpeg" in err and ".gif or .html" in err
    assert not (tmp_path / "a.mp4").exists()


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("chromium") is None, reason="needs headless Chromium (apt-get install chromium)")
def test_the_html_page_plays_in_headless_chromium(run_dir, tmp_path):
    """A screenshot after a second of the page's time differs from one at load."""
    from PIL import Image

    page = tmp_path / "a.html"
    assert main(["animate", str(run_dir), "--out", str(page), "--frames-per-revolution", "24", "--quiet"]) == 0
    shots = []
    for budget in (None, 1000):
        shot = tmp_path / f"shot{budget}.png"
        cmd = [
            "chromium",
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--window-size=1000,700",
            f"--screenshot={shot}",
            page.as_uri(),
        ]
        if budget is not None:
            cmd.insert(-1, f"--virtual-time-budget={budget}")
        subprocess.run(cmd, check=True, capture_output=True, timeout=120)
        with Image.open(shot) as im:
            shots.append(np.asarray(im.convert("RGB")))
    assert shots[0].shape == shots[1].shape and (shots[0] != shots[1]).any()


def _worn_paper(depth: float):
    """The paper's mechanism with worn joints; the hole at B worn ``depth (1 + cos 2 theta) / 2``
    in the rod's frame (m), the pins and the hole at C new."""
    from jaxcrank.numerics import wear_run as nw

    mech = jc.preset("paper-wear")
    prof = nw.profiles_of(mech)
    hole = np.zeros(np.shape(prof["B"][0]))
    hole[0] = hole[2] = depth / 2  # a_0 and a_2 (the cos 2 theta coefficient)
    return nw.with_profiles(mech, {"B": (jnp.asarray(hole), prof["B"][1]), "C": prof["C"]})


def test_a_worn_hole_is_drawn_as_it_is_worn_and_turns_with_its_body(run_dir):
    """The gap a worn joint leaves the pin is the clearance plus the hole's depth at that
    direction of the hole's body (and the round joint's is the clearance); the animation's inset
    draws that outline at every frame, turned with the rod, and the run's pin-trajectory figure
    draws it at the end."""
    from jaxcrank.runs import plots, view_cli
    from jaxcrank.views import geometry as geo

    depth = 2e-4
    mech = _worn_paper(depth)
    joints = {j.name: j for j in geo.layout(mech).joints}
    c = joints["B"].clearance  # the preset's 0.5 mm, as hole less pin radius
    phi = np.linspace(0.0, 2.0 * math.pi, 13)
    for turn in (0.0, 0.3):
        expected = c + depth * (1.0 + np.cos(2.0 * (phi - turn))) / 2.0
        np.testing.assert_allclose(geo.gap(joints["B"], phi, turn, 1.1), expected, rtol=1e-12)
    np.testing.assert_array_equal(geo.gap(joints["C"], phi, 0.3, 1.1), joints["C"].clearance)  # new: round
    round_b = {j.name: j for j in geo.layout(jc.preset("paper")).joints}["B"]
    assert round_b.wear is None
    np.testing.assert_array_equal(geo.gap(round_b, phi), round_b.clearance)

    _, cols = view_cli.read_run(run_dir)  # the paper's run: the same bodies and columns
    anim = animation.animate(cols=cols, mech=mech, per_revolution=12)
    lines = {ax.get_title().split(":")[0]: ax.get_lines() for ax in anim.fig.axes[1:]}
    assert "worn hole" in [ax.get_title() for ax in anim.fig.axes[1:] if ax.get_title().startswith("B")][0]
    for k in (0, 6):
        anim.update_frame(k)
        rod = math.radians(float(cols["rod_angle"][anim.indices[k]]))
        outline = [ln for ln in lines["B"] if ln.get_linestyle() == "-" and len(ln.get_xdata()) == 181][0]
        x, y = np.asarray(outline.get_xdata()), np.asarray(outline.get_ydata())
        np.testing.assert_allclose(np.hypot(x, y), 1e3 * (c + depth * (1 + np.cos(2 * (np.arctan2(y, x) - rod))) / 2),
                                   rtol=1e-9)  # fmt: skip
    assert not any(len(ln.get_xdata()) == 181 and ln.get_linestyle() == "-" for ln in lines["C"])
    import matplotlib.pyplot as plt

    plt.close(anim.fig)
    figs = plots.figures(cols, mech)
    fig = figs["pin_trajectories.png"]
    labels = [t.get_text() for ax in fig.axes for t in (ax.get_legend().get_texts() if ax.get_legend() else [])]
    assert labels.count("worn, at the end") == 1  # B only: C is new
    for f in figs.values():
        plt.close(f)
