"""Errors about run files (sweep tables, optimiser checkpoints) that cannot be read back."""

from __future__ import annotations


class CorruptFileError(ValueError):
    """A run file (``table.csv``, ``designs.npy``, ``checkpoint.npz``) is truncated,
    corrupted or inconsistent with the run it should continue. The message names the
    file and what is wrong. Resuming never starts over silently: move the file away
    (or choose another output directory) to start a new run."""
