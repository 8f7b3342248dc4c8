"""The round trip of a design: `jaxcrank optimize --problem design` writes result.json, and
the command it documents (`jaxcrank simulate --design DIR/result.json`) simulates that
design with the metrics of the library's own simulation of it."""

import json
import shlex

import jax
import pytest

import jaxcrank as jc
from jaxcrank.numerics.solve import as_values
from jaxcrank.runs import config
from jaxcrank.runs.cli import main


@pytest.mark.slow
def test_optimised_design_simulates_from_the_cli_with_the_library_metrics(tmp_path):
    from optim import cli as optim_cli

    cfg = tmp_path / "opt.toml"
    # the shortest settings: two iterations of the nine-variable design problem on a 2 ms window
    cfg.write_text(
        'problem = "design"\n[optimizer]\nmax_iterations = 2\n'
        '[objective]\nt_start = 0.0\nt_end = 0.002\nmethod = "pathwise"\n'
    )
    out = tmp_path / "opt"
    assert main(["optimize", "--config", str(cfg), "--out", str(out), "--no-cache", "--quiet"]) == 0
    result = json.loads((out / "result.json").read_text())

    # the documented command, as result.json spells it (`jaxcrank` is this module's main)
    argv = shlex.split(result["simulate_command"])
    assert argv[:4] == ["jaxcrank", "simulate", "--design", str(out / "result.json")]
    assert main(argv[1:] + ["--no-figures", "--quiet"]) == 0
    summary = json.loads((out / "simulate" / "summary.json").read_text())

    # the library's simulation of the same design, with the CLI's defaults (0.4 s, 10
    # samples per degree, metrics after the first revolution)
    problem, _ = optim_cli.build(optim_cli.tomllib.loads(cfg.read_text()))
    mech = problem.mechanism(jax.numpy.asarray(result["final_design_SI"]))
    # the CLI simulated exactly these parameters
    assert config.load(out / "simulate" / "config.toml") == config.from_dict(config.to_dict(mech))
    assert config.to_dict(config.load(out / "simulate" / "config.toml")) == config.to_dict(mech)
    for name, value in result["final_parameters_SI"].items():
        # a clearance is stored as hole - pin radius: equal to ~1 ulp of the 8 mm radii
        assert jc.get_parameter(mech, name) == pytest.approx(value, rel=1e-12, abs=1e-18), name
    cli = summary["metrics"]

    def library_metrics(m):
        sim = jc.simulate(m, 0.4, n_samples=14401, metrics_start=float(m.period))
        return jc.outputs.summary_metrics(sim)

    # the parameters as a config file gives them, made the program's values as the command
    # line makes them (`as_values`): the same compiled program, bit-identical metrics
    library = library_metrics(as_values(config.from_dict(config.to_dict(mech))))
    assert set(library) <= set(cli)
    for key, value in library.items():
        assert cli[key] == value, key
    # as the optimiser holds them (arrays: a differently compiled program of the same
    # equations): the impacts amplify last-bit rounding. The motion (the outputs' position
    # deviations and Eq. 19) agrees within 1 % (measured: 4e-6 to 6e-4); the impact-driven
    # peaks (contact forces, penetrations, accelerations, driving moment, the largest
    # transmission-angle error) move by up to 3.4 % and are not compared
    arrays = library_metrics(mech)
    motion = [k for k in arrays if k.endswith("_deviation_m") or k == "rms_transmission_angle_error_deg"]
    assert len(motion) == 5, motion
    for key in motion:
        assert cli[key] == pytest.approx(arrays[key], rel=1e-2, abs=1e-12), key
