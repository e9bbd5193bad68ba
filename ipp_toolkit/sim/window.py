"""A window that shows the rendered frames: the ``human`` render mode of the envs.

Matplotlib draws the RGB frames of :func:`ipp_toolkit.sim.rendering.render_state` in one
figure, updated in place; on a non-interactive backend (``Agg``, headless machines) the
figure is still drawn, without waiting between frames.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

__all__ = ["FrameWindow"]


class FrameWindow:
    """One matplotlib figure showing the latest frame.

    Args:
        title: the window's title.
        fps: frames per second to pace an interactive window at.
    """

    def __init__(self, title: str, fps: float) -> None:
        self.title = title
        self.fps = float(fps)
        self.figure: Any = None
        self._image: Any = None

    def show(self, frame: np.ndarray) -> None:
        """Show an (h, w, 3) uint8 frame (opening the window, or reopening a closed one)."""
        import matplotlib.pyplot as plt
        from matplotlib.backend_bases import FigureCanvasBase

        if self.figure is None or not plt.fignum_exists(self.figure.number):
            self.figure = plt.figure(self.title, figsize=(frame.shape[1] / 100,
                                                          frame.shape[0] / 100))
            axes = self.figure.add_axes((0, 0, 1, 1))
            axes.set_axis_off()
            self._image = axes.imshow(frame)
            with warnings.catch_warnings():  # Agg: "non-interactive, cannot be shown"
                warnings.simplefilter("ignore", UserWarning)
                plt.show(block=False)
        else:
            self._image.set_data(frame)
        self.figure.canvas.draw_idle()
        canvas = type(self.figure.canvas)
        if canvas.start_event_loop is not FigureCanvasBase.start_event_loop:  # interactive
            plt.pause(1.0 / self.fps)

    def close(self) -> None:
        """Close the window (idempotent)."""
        if self.figure is not None:
            import matplotlib.pyplot as plt

            plt.close(self.figure)
            self.figure = self._image = None
