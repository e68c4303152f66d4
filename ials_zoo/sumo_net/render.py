"""A top view of a ``sumo_net_v0`` network (``render_mode="rgb_array"``), drawn with Pillow.

Roads are grey lines (every lane of the network file); each light's incoming lanes end in a
mark coloured by the light's signal for that lane (its first link); learners' marks get a
magenta ring; vehicles are blue dots.
"""

from __future__ import annotations

import numpy as np

_BACK, _ROAD, _CAR, _LEARNER = (255, 255, 255), (200, 200, 200), (40, 90, 220), (220, 0, 220)
_SIGNAL = {"G": (0, 170, 0), "g": (120, 210, 120), "y": (240, 190, 0), "r": (210, 0, 0), "s": (210, 0, 0)}
LEGEND = (("road", _ROAD), ("car", _CAR), ("green", _SIGNAL["G"]), ("yellow", _SIGNAL["y"]),
          ("red", _SIGNAL["r"]), ("learner", _LEARNER))
"""The colours of :func:`render_network`, for legends."""


class NetworkView:
    """The fixed part of the picture (roads, scale), drawn once per network."""

    def __init__(self, network, width: int = 640):
        points = np.array([xy for shape in network.lane_shapes.values() for xy in shape] or [(0.0, 0.0)])
        self.low = points.min(axis=0) - 10.0
        span = np.maximum(points.max(axis=0) + 10.0 - self.low, 1.0)
        self.scale = width / float(span.max())
        self.size = (int(span[0] * self.scale) + 1, int(span[1] * self.scale) + 1)
        self.network = network
        from PIL import Image, ImageDraw

        self.base = Image.new("RGB", self.size, _BACK)
        draw = ImageDraw.Draw(self.base)
        for shape in network.lane_shapes.values():
            if len(shape) > 1:
                draw.line([self.pixel(xy) for xy in shape], fill=_ROAD, width=2)

    def pixel(self, xy) -> tuple[int, int]:
        x = (xy[0] - self.low[0]) * self.scale
        y = self.size[1] - 1 - (xy[1] - self.low[1]) * self.scale  # SUMO's y points north
        return int(x), int(y)

    def draw(self, data: dict, learners=()) -> np.ndarray:
        """``data = {"xy": [(x, y), ...] vehicles, "signals": {tls: state string}}``."""
        from PIL import ImageDraw

        img = self.base.copy()
        draw = ImageDraw.Draw(img)
        for light in self.network.lights:
            state = data["signals"].get(light.id, "")
            for lane in light.lanes:
                shape = self.network.lane_shapes.get(lane)
                links = [k for i, _, k in light.links if i == lane and k < len(state)]
                if not shape or not links:
                    continue
                x, y = self.pixel(shape[-1])
                if light.id in learners:
                    draw.ellipse([x - 6, y - 6, x + 6, y + 6], outline=_LEARNER, width=2)
                draw.ellipse([x - 3, y - 3, x + 3, y + 3], fill=_SIGNAL.get(state[links[0]], _ROAD))
        for xy in data["xy"]:
            x, y = self.pixel(xy)
            draw.ellipse([x - 2, y - 2, x + 2, y + 2], fill=_CAR)
        return np.asarray(img, dtype=np.uint8)


__all__ = ["LEGEND", "NetworkView"]
