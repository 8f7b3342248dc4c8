"""Validation rigs: runs that check the model against facts, not parts of a simulation.

- [`wall_impact`][jaxcrank.analysis.validation.wall_impact]: a free pin hitting a bearing wall,
  each contact law's achieved restitution against the exact relation;
- [`memory_audit`][jaxcrank.analysis.validation.memory_audit]: the approach-speed memory against
  the true normal speed at every contact onset of a run;
- [`events`][jaxcrank.analysis.validation.events]: what both share, the dense solve and the
  location of zero crossings by bisection.
"""
