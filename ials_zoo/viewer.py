"""Episode pictures for any domain: annotated frames and GIFs.

Every GS renders ``rgb_array`` frames; :func:`annotate` puts a caption bar above a frame (the
step, the learners' reward and return so far) and the domain's colour legend below it, and
:func:`save_gif` writes frames as an animated GIF with a real frame duration.
"""

from __future__ import annotations

import os

import numpy as np

from ials_zoo.errors import BadInput
from ials_zoo.utils import atomic_path

_BAR = (250, 250, 250)
_TEXT = (20, 20, 20)


def annotate(frame: np.ndarray, caption: str, legend=()) -> np.ndarray:
    """``frame`` (H x W x 3 uint8) with ``caption`` in a bar above it and ``legend``
    (``(label, (r, g, b))`` pairs) as coloured swatches in a bar below it."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(np.asarray(frame, dtype=np.uint8))
    w, h = img.size
    line = 14
    legend_rows = []
    x, row = 4, []
    for label, colour in legend:
        width = 14 + 6 * len(label) + 10
        if row and x + width > w:
            legend_rows.append(row)
            x, row = 4, []
        row.append((x, label, tuple(int(c) for c in colour)))
        x += width
    if row:
        legend_rows.append(row)
    top, bottom = line + 6, line * len(legend_rows) + (4 if legend_rows else 0)
    out = Image.new("RGB", (w, h + top + bottom), _BAR)
    out.paste(img, (0, top))
    draw = ImageDraw.Draw(out)
    draw.text((4, 3), caption, fill=_TEXT)
    for r, items in enumerate(legend_rows):
        y = top + h + 2 + r * line
        for x, label, colour in items:
            draw.rectangle([x, y + 2, x + 9, y + 11], fill=colour, outline=_TEXT)
            draw.text((x + 13, y + 1), label, fill=_TEXT)
    return np.asarray(out)


def save_gif(frames, path: str | os.PathLike, fps: float = 5.0) -> None:
    """Write RGB ``frames`` (H x W x 3 uint8 arrays) to ``path`` as a looping GIF, each frame
    shown ``1 / fps`` seconds; atomic (nothing half-written is left at ``path``)."""
    from PIL import Image

    frames = list(frames)
    if not frames:
        raise BadInput("save_gif needs at least one frame")
    if not fps > 0:
        raise BadInput(f"fps must be > 0, got {fps!r}")
    images = [Image.fromarray(np.asarray(f, dtype=np.uint8)) for f in frames]
    with atomic_path(path, suffix=".gif") as tmp:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:],
                       duration=max(20, int(round(1000 / fps))), loop=0)


def record_episode(env, actions_fn=None, seed: int | None = None, legend=()) -> list[np.ndarray]:
    """Run one episode of an ``rgb_array`` GS and return its annotated frames.

    ``actions_fn(obs) -> {agent: action}``; default: uniformly random actions."""
    if env.render_mode != "rgb_array":
        raise BadInput(f"record_episode needs render_mode='rgb_array', got {env.render_mode!r}")
    obs, _ = env.reset(seed=seed)
    total, t = 0.0, 0
    frames = [annotate(env.render(), "step 0", legend)]
    while env.agents:
        actions = (actions_fn(obs) if actions_fn is not None
                   else {a: env.action_space(a).sample() for a in env.agents})
        obs, rewards, *_ = env.step(actions)
        t += 1
        step_reward = float(np.mean(list(rewards.values()))) if rewards else 0.0
        total += step_reward
        frames.append(annotate(env.render(), f"step {t}  reward {step_reward:.2f}  return {total:.2f}",
                               legend))
    return frames


__all__ = ["annotate", "record_episode", "save_gif"]
