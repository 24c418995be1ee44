"""Layout checks of matplotlib figures through the renderer (test_figure_layout.py and the main
job's parts): every title and legend inside its figure, no legend over what the figure draws."""

import contextlib
from pathlib import Path

import numpy as np
import pytest


def _titles_and_legends(fig):
    """``(what, artist)`` of every visible title, suptitle and legend of ``fig``."""
    found = []
    texts = [fig._suptitle, fig._supxlabel, fig._supylabel]  # noqa: SLF001
    for ax in fig.axes:
        texts += [ax.title, ax._left_title, ax._right_title]  # noqa: SLF001
        if ax.get_legend() is not None:
            found.append((f"the legend of axes {ax.get_label() or fig.axes.index(ax)}", ax.get_legend()))
    found += [(f"figure legend {i}", leg) for i, leg in enumerate(fig.legends)]
    found += [(f"title {t.get_text()!r}", t) for t in texts if t is not None and t.get_text() and t.get_visible()]
    return [(what, a) for what, a in found if a.get_visible()]


def outside_problems(fig, tol: float = 0.5) -> list[str]:
    """Titles and legends of ``fig`` that reach beyond the figure (clipped when saved)."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    box = fig.bbox
    problems = []
    for what, artist in _titles_and_legends(fig):
        b = artist.get_window_extent(renderer)
        if b.x0 < box.x0 - tol or b.y0 < box.y0 - tol or b.x1 > box.x1 + tol or b.y1 > box.y1 + tol:
            problems.append(f"{what} reaches beyond the figure: [{b.x0:.0f}, {b.x1:.0f}] × [{b.y0:.0f}, "
                            f"{b.y1:.0f}] px, the figure [0, {box.x1:.0f}] × [0, {box.y1:.0f}]")
    return problems


def covering_problems(fig, *, margin: int = 2) -> list[str]:
    """Legends of ``fig`` drawn over something else: the figure drawn without the legend has
    pixels other than the background inside the legend's box (bars, arrows, lines, markers, text
    of any kind). For 2-D figures on a white background."""
    fig.canvas.draw()
    legends = [(what, a) for what, a in _titles_and_legends(fig) if not hasattr(a, "get_text")]
    problems = []
    engine = fig.get_layout_engine()
    if engine is not None:  # (the layout as drawn: without the legend, a layout engine would fill its place)
        fig.set_layout_engine("none")
    for what, legend in legends:
        b = legend.get_window_extent(fig.canvas.get_renderer())
        legend.set_visible(False)
        try:
            fig.canvas.draw()
            img = np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(int)
        finally:
            legend.set_visible(True)
        h, w = img.shape[:2]
        x0, x1 = max(int(np.ceil(b.x0)) + margin, 0), min(int(np.floor(b.x1)) - margin, w)
        y0, y1 = max(h - int(np.floor(b.y1)) + margin, 0), min(h - int(np.ceil(b.y0)) - margin, h)
        region = img[y0:y1, x0:x1]
        drawn = int((region.min(axis=-1) < 235).sum()) if region.size else 0
        if drawn:
            problems.append(f"{what} lies over {drawn} drawn pixels of the figure")
    if engine is not None:
        fig.set_layout_engine(engine)
    fig.canvas.draw()
    return problems


def layout_problems(fig, *, covering: bool = True) -> list[str]:
    """Every title or legend outside ``fig``, and (``covering``) every legend over its drawing."""
    return outside_problems(fig) + (covering_problems(fig) if covering else [])


@contextlib.contextmanager
def checking_part_figures(*, covering: bool = True):
    """Inside: every figure a main-job part records (``ctx.figure``) is checked before it is
    saved; yields ``{filename: problems}``."""
    from pmpjax._app.parts import PartContext

    found: dict[str, list[str]] = {}
    record = PartContext.figure

    def figure(self, fig, filename, *args, **kwargs):
        if not isinstance(fig, str | Path):
            found[filename] = layout_problems(fig, covering=covering)
        return record(self, fig, filename, *args, **kwargs)

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(PartContext, "figure", figure)
        yield found
