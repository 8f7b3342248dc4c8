"""Seeing a mechanism: its drawing at a driver angle ([`jaxcrank.views.drawing`][]) and its
motion from a run ([`jaxcrank.views.animation`][]), both from the geometry in
[`jaxcrank.views.geometry`][] (world positions of every body point, from the assembly or
from a run's columns). These modules import matplotlib; nothing in the simulator imports
them."""
