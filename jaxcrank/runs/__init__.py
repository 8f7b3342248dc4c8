"""The runs: sweeps and their samplers and spec files, TOML configuration, the
compilation cache, figures and the command line. Builds on every other layer."""
