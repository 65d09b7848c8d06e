"""Where the AEC flattener lived before 0.2.0: it is :class:`marl_vertiport.flat.FlatAEC` now,
the project's one flattener, and this module only keeps the old import path."""

from agents.common.names import note_renamed
from marl_vertiport.flat import FlatAEC as FlatObservation
from marl_vertiport.flat import flatten_arrays as flatten

__all__ = ["FlatObservation", "flatten"]

note_renamed("agents.interop.flat.FlatObservation", "marl_vertiport.flat.FlatAEC", "class")
