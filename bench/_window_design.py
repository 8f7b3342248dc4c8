"""The transient-window design objective of the earlier design studies
(``bench/design_study.py``, ``bench/design_gradient_terms.py``): the (0.02, 0.04] s window
from rest with five 2 ms ensemble windows (tsit5), and its forward evaluator."""

from __future__ import annotations

#: the studies' evaluation window: (0.02, 0.04] s, five 2 ms ensemble windows solved with tsit5
OBJECTIVE = dict(t_start=0.02, t_end=0.04, windows=5, window_solver="tsit5")
TINY = dict(t_start=0.0, t_end=2e-3, windows=2, window=1e-3, window_solver="tsit5")
FIVE = ("rod_length", "min_transmission_angle", "clearance_B", "clearance_C", "friction.coefficient")


def build(name: str, objective: dict):
    """``paper_2var``, ``design_5var`` or ``design_9var`` with the ensemble objective of the
    ``[objective]`` keys ``objective``."""
    import jax

    jax.config.update("jax_enable_x64", True)
    from optim.objective_config import objective_from_config
    from optim.presets import design_problem, paper_problem

    obj = objective_from_config({"method": "ensemble", **objective})
    if name.startswith("paper"):
        return paper_problem(obj)
    if name == "design_5var":
        return design_problem(obj, variables=FIVE)
    return design_problem(obj)


def evaluator(problem):
    """Jitted ``x (SI) -> (objective deg, ok)``: one forward solve from rest (the pathwise
    value over the objective's window), failures reported."""
    import jax

    from optim.search import pathwise_of

    pathwise = pathwise_of(problem.objective)

    def f(x):
        rms, ok = pathwise.evaluate(problem.mechanism(x))
        return problem.loss(rms) + problem.cost(x), ok

    return jax.jit(f)
