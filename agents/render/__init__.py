"""Animated GIF (or MP4) of one episode of a controller, with a readable overlay
(``python -m agents.render --help``).

* ``camera``: pybullet's view and a camera placed so the airspace fits;
* ``frames``: one frame, the engine's image with labels and the side panel;
* ``video``: recording an episode's frames, writing GIF or MP4;
* ``cli``: the command line.
"""

from agents.render.camera import Camera, fit_camera
from agents.render.cli import main, parse_size
from agents.render.frames import FrameComposer
from agents.render.style import hhmm
from agents.render.video import GifQuantiser, RenderError, record_episode, write_video

__all__ = ["Camera", "FrameComposer", "GifQuantiser", "RenderError", "fit_camera", "hhmm", "main",
           "parse_size", "record_episode", "write_video"]
