"""The numerics: the solve (diffrax, the Rosenbrock solver, small dense linear algebra),
metrics tracked during the solve, and the XLA runtime options. Builds on
[`jaxcrank.physics`][] and the metric definitions of [`jaxcrank.analysis.metrics`][]."""
