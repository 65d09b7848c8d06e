"""Where the look-ahead controller lived before 0.2.0 (``handback``): it is
:mod:`agents.controllers.lookahead` now, and this module only keeps the old import path."""

from agents.common.names import note_renamed
from agents.controllers.lookahead import HandbackController, LookaheadController

__all__ = ["HandbackController", "LookaheadController"]

note_renamed("agents.controllers.handback", "agents.controllers.lookahead", "module")
