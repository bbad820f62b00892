"""``laneshift eval --video``: the first greedy episodes of an evaluation as an animated GIF.

A :class:`GifRecorder` is the ``recorder`` of ``evaluate_policy``: it sees the very episodes the
rates are counted on (same seeds, same actions), draws each with the env's ``render()`` (the
top-down view of ``render_mode="rgb_array"``, drawn off-screen: real frames headless, whatever
``SDL_VIDEODRIVER`` says) and writes them with their real-time durations. An episode of n steps
gives n + 1 frames (the start, then the outcome of each step), or every k-th of them with
``fps`` below the policy frequency (k = policy frequency / fps, rounded; the last frame is always
kept, so the outcome is seen); the last frame of each episode is held ``hold_s`` longer.

Why a GIF written with Pillow: Pillow comes with matplotlib (a dependency already), is a
well-kept library and writes animated GIFs itself, while an MP4 needs an ffmpeg binding (imageio
with imageio-ffmpeg, PyAV, moviepy: tens of MB, none installed). The top-down view has a handful
of flat colours, so a GIF's palette loses nothing and its compression keeps a 300-step episode
small, and a GIF plays inline on GitHub and in any browser.

    laneshift eval --checkpoint best.safetensors --scenario straight --episodes 1 --video run.gif

Room: the tools (studies). May import: anything in laneshift, numpy, Pillow.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

#: Animation formats ``--video`` writes (by the path's suffix).
VIDEO_SUFFIXES = (".gif",)


def check_video_path(path: str | Path) -> Path:
    """``path`` if ``--video`` can write it, else ValueError saying why."""
    path = Path(path)
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        why = " (no MP4 writer is installed; GIF only)" if path.suffix.lower() == ".mp4" else ""
        raise ValueError(f"{path}: write a .gif{why}")
    return path


class GifRecorder:
    """Records the first ``episodes`` episodes of an evaluation; :meth:`write` saves the GIF.

    ``fps``: frames per second of real time (None: one frame per policy step, the env's policy
    frequency, 10 Hz on the lane-change roads). ``scale``: image size factor (1: 600 x 300)."""

    def __init__(self, path: str | Path, episodes: int = 1, fps: float | None = None, scale: float = 1.0,
                 hold_s: float = 1.0) -> None:
        if episodes < 1:
            raise ValueError(f"episodes must be >= 1, not {episodes}")
        if fps is not None and fps <= 0:
            raise ValueError(f"fps must be > 0, not {fps}")
        if not 0 < scale <= 1:
            raise ValueError(f"scale must be in (0, 1], not {scale}")
        self.path = check_video_path(path)
        self.episodes, self.fps, self.scale, self.hold_s = episodes, fps, scale, hold_s
        self.every = 0  # record every k-th step, known once the env's policy frequency is
        self.frame_ms = 0.0
        self._images: list[Any] = []  # palette images (a byte a pixel, not three)
        self._durations: list[int] = []
        self._episode_frames = 0
        self.recorded: list[dict] = []

    def frame(self, episode: int, step: int, env: Any, last: bool) -> None:
        if not self.every:
            hz = float(getattr(env.unwrapped, "policy_frequency", 0) or env.metadata.get("render_fps", 10))
            self.every = max(1, round(hz / self.fps)) if self.fps else 1
            self.frame_ms = 1000.0 * self.every / hz
        if step % self.every and not last:
            return
        rgb = env.render()
        if rgb is None:
            raise ValueError(f"{env.spec.id if env.spec else env}: render() drew nothing (no rgb_array view)")
        self._add(np.asarray(rgb, dtype=np.uint8))

    def _add(self, rgb: np.ndarray) -> None:
        from PIL import Image

        img = Image.fromarray(rgb)
        if self.scale != 1:  # nearest: no blended edge colours, the palette stays the view's few
            img = img.resize((max(1, round(img.width * self.scale)), max(1, round(img.height * self.scale))),
                             Image.Resampling.NEAREST)
        # Median cut gives each of the view's (<= 256) colours its own palette entry: lossless.
        self._images.append(img.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE))
        self._durations.append(round(self.frame_ms))
        self._episode_frames += 1

    def episode_end(self, episode: int, seed: int, steps: int, outcome: dict) -> None:
        if self._durations:
            self._durations[-1] += round(1000 * self.hold_s)  # hold the outcome before the next one
        self.recorded.append({"episode": episode, "seed": seed, "steps": steps, "frames": self._episode_frames,
                              **outcome})
        self._episode_frames = 0

    def write(self) -> dict:
        """Save the GIF (looping); what was written: path, frames, bytes, fps, and the episodes."""
        if not self._images:
            raise ValueError(f"{self.path}: no frames were recorded")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        first, *rest = self._images
        # optimize=False: the palettes are already minimal; Pillow still stores each frame as its
        # changed rectangle over the previous one (and merges a frame identical to the previous).
        first.save(self.path, save_all=True, append_images=rest, duration=self._durations, loop=0,
                   optimize=False, disposal=1)
        from PIL import Image

        with Image.open(self.path) as written:  # what the file holds (identical neighbours merged)
            frames = written.n_frames
        return {"path": str(self.path), "frames": frames, "bytes": self.path.stat().st_size,
                "fps": round(1000.0 / self.frame_ms, 3), "size": list(first.size), "episodes": self.recorded}
