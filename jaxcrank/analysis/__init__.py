"""The analysis: metric definitions, outputs as functions of a solution, and the
validation rigs (impact harness, approach-speed audit). Builds on
[`jaxcrank.physics`][] and [`jaxcrank.numerics`][]."""
