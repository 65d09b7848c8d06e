"""Recording an episode's frames and writing them as an animated GIF or an MP4."""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable

import numpy as np
from PIL import Image

from agents.controllers.decisions import DecisionLog
from agents.controllers.episode import run_episode
from marl_vertiport.sim.core import VertiportSim
from agents.render.frames import FrameComposer
from agents.render.style import ACT_BG, AMBER, BG, BLUE, DIM, GREEN, RED, ROW_BG, SKY, TEXT



class RenderError(Exception):
    """A user error the CLI reports in one line (exit status 2)."""


def run_cli(parser: Any, run: Callable[[Any], int], argv: list[str] | None) -> int:
    """Parse ``argv`` with ``parser`` and ``run`` the arguments; a :class:`RenderError` is
    printed as one line and exits with status 2 (the render commands' main)."""
    args = parser.parse_args(argv)
    try:
        return run(args)
    except RenderError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2



# ====================================================================== recording
class _Done(Exception):
    """Raised from the step callback once the last frame is recorded."""


def record_episode(env: Any, policy: Any, seed: int, composer_factory: Callable[[VertiportSim], FrameComposer],
                   start_step: int, n_steps: int, every: int, progress: bool = True,
                   convert: Callable[[Image.Image], Any] | None = None,
                   log: DecisionLog | None = None,
                   after_step: Callable[[str, int, Any], None] | None = None) -> list[Any]:
    """Run the episode with ``run_episode`` (as evaluation does), fast-forward
    ``start_step`` steps without rendering (with a progress bar of its own), then compose a
    frame after every ``every``-th of the next ``n_steps`` steps; the episode stops after the
    last frame. ``after_step`` is called after every step too (a timeline's recorder).

    Args:
        composer_factory: builds the :class:`FrameComposer` from the simulator.
        convert: applied to each RGB frame as it is made (e.g. a :class:`GifQuantiser`, so
            long recordings keep 1 byte per pixel in memory).
        log: a :class:`~agents.controllers.decisions.DecisionLog` of ``policy``: it logs every
            turn from the day's start to the last frame, and each frame shows its decision.

    Returns:
        The frames, RGB PIL images (or what ``convert`` made of them).
    """
    frames: list[Any] = []
    n_frames = len(range(0, n_steps, every))
    state: dict[str, Any] = {"composer": None, "bar": None, "ff": None}
    last = start_step + (n_frames - 1) * every

    def on_step(agent: str, action: int, env_: Any) -> None:
        if log is not None:
            log.after_step(agent, action, env_)
        if after_step is not None:
            after_step(agent, action, env_)
        sim = env_.unwrapped.sim
        k = sim.step_count - 1  # index of the step just taken
        if k < start_step:
            if progress and state["ff"] is None:
                from tqdm import tqdm

                state["ff"] = tqdm(total=start_step, unit="step", desc="fast-forward",
                                   file=sys.stderr, leave=False)
            if state["ff"] is not None:
                state["ff"].update(1)
            return
        if state["ff"] is not None:
            state["ff"].close()
            state["ff"] = None
        if (k - start_step) % every:
            return
        if state["composer"] is None:
            state["composer"] = composer_factory(sim)
            if progress:
                from tqdm import tqdm

                state["bar"] = tqdm(total=n_frames, unit="frame", desc="rendering",
                                    file=sys.stderr, leave=True)
        reward = float(env_.rewards.get(agent, 0.0)) if hasattr(env_, "rewards") else None
        frame = state["composer"].compose(step_reward=reward,
                                          decision=log.last if log is not None else None)
        frames.append(convert(frame) if convert is not None else frame)
        if state["bar"] is not None:
            state["bar"].update(1)
        if k >= last:
            raise _Done

    try:
        run_episode(env, policy, seed, after_step=on_step,
                    before_step=log.before_step if log is not None else None)
    except _Done:
        pass
    finally:
        for bar in (state["ff"], state["bar"]):
            if bar is not None:
                bar.close()
    return frames


# ====================================================================== writing
def _mp4_backend() -> str | None:
    """``"ffmpeg"`` (imageio-ffmpeg) or ``"pyav"`` if imageio can write MP4 here, else ``None``."""
    for module, name in (("imageio_ffmpeg", "ffmpeg"), ("av", "pyav")):
        try:
            __import__(module)
        except ImportError:
            continue
        return name
    return None


class GifQuantiser:
    """Maps RGB frames to one 256-colour palette shared by the whole animation (no flicker
    between frames, and runs of equal pixels compress well). The palette comes from the first
    frame plus shades of every body and overlay colour, so colours that appear later (a red
    delay, a vehicle coming back) have an entry. No dithering: flat colours stay flat."""

    def __init__(self, colours: list[tuple[int, int, int]] | None = None) -> None:
        self.colours = list(colours or [])
        self.palette: Image.Image | None = None

    def _build(self, first: Image.Image) -> Image.Image:
        w, h = first.size
        extra = self.colours + [BG, ROW_BG, ACT_BG, TEXT, DIM, RED, AMBER, GREEN, BLUE,
                                SKY, (255, 255, 255), (0, 0, 0), (245, 245, 245)]
        shades = [tuple(int(v * f) for v in c) for c in extra for f in np.linspace(0.35, 1.0, 8)]
        strip = np.zeros((max(8, h // 4), w, 3), dtype=np.uint8)
        for k, c in enumerate(shades):
            strip[:, k * w // len(shades):(k + 1) * w // len(shades)] = c
        mosaic = Image.new("RGB", (w, h + strip.shape[0]))
        mosaic.paste(first, (0, 0))
        mosaic.paste(Image.fromarray(strip), (0, h))
        return mosaic.quantize(colors=256, method=Image.Quantize.MEDIANCUT,
                               dither=Image.Dither.NONE)

    def __call__(self, frame: Image.Image) -> Image.Image:
        if self.palette is None:
            self.palette = self._build(frame)
        return frame.quantize(palette=self.palette, dither=Image.Dither.NONE)


def write_video(frames: list[Image.Image], path: Path, fps: float,
                colours: list[tuple[int, int, int]] | None = None) -> None:
    """Write ``frames`` to ``path`` (.gif or .mp4) through a temp file and ``os.replace``.

    GIF frames may be RGB (quantised here) or already palette images (``GifQuantiser``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=suffix, dir=path.parent)
    os.close(fd)
    try:
        if suffix == ".gif":
            quantise = GifQuantiser(colours)
            quantised = [f if f.mode == "P" else quantise(f) for f in frames]
            duration = max(20, int(round(1000.0 / fps)))
            quantised[0].save(tmp, format="GIF", save_all=True, append_images=quantised[1:],
                              duration=duration, loop=0, optimize=False, disposal=1)
        elif suffix == ".mp4":
            arrays = np.stack([np.asarray(f.convert("RGB")) for f in frames])
            h, w = arrays.shape[1] // 2 * 2, arrays.shape[2] // 2 * 2  # H.264 needs even sizes
            arrays = np.ascontiguousarray(arrays[:, :h, :w])
            if _mp4_backend() == "ffmpeg":
                import imageio.v2 as iio2

                iio2.mimwrite(tmp, list(arrays), format="FFMPEG", fps=fps, codec="libx264",
                              macro_block_size=2)
            else:
                import imageio.v3 as iio

                iio.imwrite(tmp, arrays, plugin="pyav", codec="libx264", fps=fps)
        else:  # pragma: no cover - checked by main
            raise RenderError(f"unsupported output format {suffix!r}")
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


