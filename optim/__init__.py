"""Design optimisation on top of jaxcrank: the paper's Eq. 19 objective with a
trend-following ensemble gradient (objective), design problems with bounds and
linear constraints (problem), many-variable problems with nonlinear
constraints held by reparametrisation (design), the optax loop with checkpoints (optimize), vmap grid
search (search), 1-D scans (scans) and ``jaxcrank optimize`` (cli)."""

import jaxcrank  # noqa: F401  (enables float64 before any array is made)
