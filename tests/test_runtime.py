"""The XLA CPU setting applied at import (jaxcrank.numerics.runtime)."""

import os
import platform
import subprocess
import sys

import jax
import jax.numpy as jnp
import pytest

import jaxcrank as jc
from jaxcrank import runtime, solve

ENTRY = f"{runtime.OPTION}={runtime.THRESHOLD_BYTES}"
ISA = "--xla_cpu_max_isa=AVX"


@pytest.mark.parametrize(
    "flags, expected",
    [
        ("", f"{ISA} --xla_backend_extra_options={ENTRY}"),
        (
            "--xla_force_host_platform_device_count=4",
            f"--xla_force_host_platform_device_count=4 {ISA} --xla_backend_extra_options={ENTRY}",
        ),
        (
            "--xla_backend_extra_options=foo=1 --xla_dump_to=/tmp/x",
            f"--xla_backend_extra_options=foo=1,{ENTRY} --xla_dump_to=/tmp/x {ISA}",
        ),
        ("--xla_backend_extra_options=", f"--xla_backend_extra_options={ENTRY} {ISA}"),
        (
            f"--xla_backend_extra_options={runtime.OPTION}=65536",
            f"--xla_backend_extra_options={runtime.OPTION}=65536 {ISA}",
        ),
        ("--xla_cpu_max_isa=AVX512", f"--xla_cpu_max_isa=AVX512 --xla_backend_extra_options={ENTRY}"),
    ],
)
def test_with_options_adds_what_is_missing_and_keeps_the_rest(flags, expected):
    assert runtime.with_options(flags) == expected


def test_configure_respects_user_opt_out_and_other_machines():
    both = f"--xla_backend_extra_options={runtime.OPTION}=4096 --xla_cpu_max_isa=SSE4_2"
    user = {"XLA_FLAGS": both}
    assert runtime.configure(user, machine="x86_64") == "user"
    assert user["XLA_FLAGS"] == both
    kept = {"XLA_FLAGS": "--xla_dump_to=/tmp/x", runtime.OPT_OUT: "1"}
    assert runtime.configure(kept, machine="x86_64") == "kept"
    assert kept["XLA_FLAGS"] == "--xla_dump_to=/tmp/x"
    arm = {}
    assert runtime.configure(arm, machine="arm64") == "not x86"
    assert arm == {}


def test_configure_after_backend_start_warns_and_leaves_flags():
    jnp.zeros(1).block_until_ready()  # the backend has started in this process
    environ = {}
    if jax.default_backend() == "cpu":
        with pytest.warns(RuntimeWarning, match="imported after JAX started"):
            assert runtime.configure(environ, machine="x86_64") == "too late"
    else:
        assert runtime.configure(environ, machine="x86_64") == "too late"
    assert "XLA_FLAGS" not in environ


def _compiled_solve_text(solver=solve.DEFAULTS.solver_name):
    mech = jc.paper()
    ts = solve.sample_times(mech, t1=1e-3)
    return (
        jax.jit(lambda m: solve.simulate(m, ts=ts, options=solve.SolveOptions.from_text(solver), throw=False).ys)
        .lower(mech)
        .compile()
        .as_text()
    )


X86 = platform.machine().lower() in ("x86_64", "amd64")


@pytest.mark.skipif(jax.default_backend() != "cpu" or not X86, reason="x86 CPU compiler options")
@pytest.mark.parametrize("solver", ["tsit5", "rodas4", pytest.param("kvaerno5", marks=pytest.mark.slow)])
def test_solver_loop_is_one_kernel_in_this_process(solver):
    """The explicit default and both stiff solvers: no LAPACK call or matrix-product
    fusion inside the loop (jaxcrank.numerics.linalg, rosenbrock._combine) keeps it on the
    thunk runtime."""
    # conftest imports jaxcrank first, so the options are in force here ("user" when the
    # parent process, e.g. pytest-xdist's controller, already put them in XLA_FLAGS)
    flags = os.environ.get("XLA_FLAGS", "")
    assert runtime.OPTION in flags and "--xla_cpu_max_isa" in flags, runtime.status
    text = _compiled_solve_text(solver)
    entry = text[text.index("ENTRY") :]
    assert 'xla_cpu_small_call="true"' in text
    assert " while(" not in entry  # diffrax's loop became one kernel


_CHILD = """
import jax
import jaxcrank
from jaxcrank import runtime
from tests.test_runtime import _compiled_solve_text
text = _compiled_solve_text()
print(runtime.status, " while(" in text[text.index("ENTRY"):])
"""


@pytest.mark.skipif(not X86, reason="x86 CPU compiler options")
@pytest.mark.parametrize("opt_out, expected", [("", "set False"), ("1", "kept True")])
def test_fresh_process(opt_out, expected):
    """A fresh Python: ``import jaxcrank`` makes the solver loop one kernel; with the
    opt-out the loop stays a while loop of the thunk runtime."""
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", runtime.OPT_OUT)}
    env.update(JAX_PLATFORMS="cpu", **{runtime.OPT_OUT: opt_out})
    root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    out = subprocess.run([sys.executable, "-c", _CHILD], env=env, cwd=root, capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip().splitlines()[-1] == expected
