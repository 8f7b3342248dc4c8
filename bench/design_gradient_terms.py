"""Which objective term's ensemble gradient disagrees with the objective's slopes?

``python bench/design_gradient_terms.py [--out bench/results/design_gradient_terms.json]``

At projected Adam's best design of ``bench/results/design_study.json`` (nine
variables, the benchmark's window): each :data:`optim.design.TERMS` entry's
ensemble gradient (:class:`optim.ensemble.Ensemble` in reverse mode) against
secant slopes of the same term from the forward solve over +-delta along every
scaled coordinate (clipped to the box), in term units per unit of the scaled variable.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import _window_design as B  # noqa: E402


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=ROOT / "bench" / "results" / "design_gradient_terms.json")
    ap.add_argument("--delta", type=float, default=0.05)
    args = ap.parse_args(argv)
    import dataclasses

    import diffrax
    import jax
    import jax.numpy as jnp

    from optim.design import TERMS
    from optim.search import pathwise_of

    study = json.loads((ROOT / "bench/results/design_study.json").read_text())
    prob = B.build("design_9var", B.OBJECTIVE)
    u0 = np.asarray(prob.to_unit(np.asarray(study["optimum"]["adam_design_SI"])))
    pathwise = prob.with_objective(pathwise_of(prob.objective))
    terms = jax.jit(lambda u: jnp.stack([pathwise.term_values(prob.from_unit(u))[k] for k in TERMS]))
    reverse = prob.with_objective(
        dataclasses.replace(prob.objective, window_adjoint=diffrax.RecursiveCheckpointAdjoint())
    )
    reverse_terms = jax.jacrev(lambda u: jnp.stack([reverse.term_values(prob.from_unit(u))[k] for k in TERMS]))
    jac = np.asarray(jax.jit(reverse_terms)(jnp.asarray(u0)))
    secant = np.zeros_like(jac)
    for j in range(prob.n):
        lo, hi = u0.copy(), u0.copy()
        lo[j], hi[j] = max(u0[j] - args.delta, 0.0), min(u0[j] + args.delta, 1.0)
        secant[:, j] = (np.asarray(terms(hi)) - np.asarray(terms(lo))) / (hi[j] - lo[j])
    w = np.asarray([prob.weight_of()[k] for k in TERMS])
    out = {
        "command": "python bench/design_gradient_terms.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "objective": B.OBJECTIVE,
        "design_unit": u0.tolist(),
        "names": list(prob.names),
        "terms": list(TERMS),
        "weights_deg_per_unit": w.tolist(),
        "values": np.asarray(terms(u0)).tolist(),
        "ensemble_gradient": jac.tolist(),
        "secant_slope": secant.tolist(),
        "delta_scaled": args.delta,
        "sign_agreement": (np.sign(jac) == np.sign(secant)).tolist(),
        "weighted_ensemble_gradient_deg": (w[:, None] * jac).tolist(),
        "weighted_secant_slope_deg": (w[:, None] * secant).tolist(),
        "load_average": os.getloadavg(),
    }
    args.out.write_text(json.dumps(out, indent=1))
    for k, t in enumerate(TERMS):
        print(t, "weighted grad", np.round(w[k] * jac[k], 4), "\n   weighted secant", np.round(w[k] * secant[k], 4))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
