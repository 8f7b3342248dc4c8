"""Runs: sweeps and their sampling and specs, configuration files, the compilation
cache, plots and the command line. Builds on :mod:`jaxcrank.physics`,
:mod:`jaxcrank.numerics` and :mod:`jaxcrank.analysis`."""
