# SPDX-License-Identifier: Apache-2.0
"""What a reader needs from a PNG the commands write, checked on its matplotlib Figure at the
dots per inch it was saved with (`figure_problems`), and the hook that keeps every saved
figure (`SavedFigures`).

The rules (test_pictures checks every PNG of the commands with them):

- text size: every drawn text is at least `MIN_PT` points when the PNG is shown at 100 % on a
  screen of `SCREEN_DPI` pixels per inch (the CSS pixel: browsers and image viewers), i.e.
  font size [pt] x saved dpi / `SCREEN_DPI` >= `MIN_PT`;
- units: every x or y axis (twin and secondary axes and colourbars included) that draws
  numeric tick labels has a label holding its unit in square brackets, `[-]` for a
  dimensionless quantity or a count (`UNIT`). Axes whose drawn tick labels are all names, not
  numbers (categories, unit ids), and axes without tick labels need none;
- legend: every plotted series that carries a label (a Line2D, a collection or a patch whose
  label does not start with '_', matplotlib's mark of an unlabelled artist) is named in a
  legend of its axes or figure, or is the mappable of a colourbar;
- inside: no drawn text extends outside the figure (its rendered extent, 1 px of slack);
- upright: no drawn text reads upside down or top to bottom: its angle on screen, in
  (-180, 180], lies in (-90, 90]; axis labels and colourbar labels may also be at -90
  (read bottom to top like a y label turned the other way, matplotlib's `rotation=270`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import Collection
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.text import Text

MIN_PT = 8.0  # smallest text a reader reads at a glance [pt]
SCREEN_DPI = 96.0  # pixels per inch of a PNG shown at 100 % (CSS reference pixel)
UNIT = re.compile(r"\[[^\[\]]+\]")  # '[Hz]', '[dB re 1 Pa²/Hz]', '[-]'
SLACK_PX = 1.0


@dataclass
class SavedFigures:
    """The figures saved while it is installed (`install`): (figure, path, dpi) each."""

    saved: list[tuple[Figure, Path, float]] = field(default_factory=list)

    def install(self, monkeypatch) -> SavedFigures:
        """Patch `Figure.savefig` to keep each figure it saves (then save it as before)."""
        original = Figure.savefig
        saved = self.saved

        def savefig(fig, fname, *args, **kwargs):
            dpi = kwargs.get("dpi")
            saved.append((fig, Path(fname), float(fig.dpi if dpi in (None, "figure") else dpi)))
            return original(fig, fname, *args, **kwargs)

        monkeypatch.setattr(Figure, "savefig", savefig)
        return self

    def named(self, name: str) -> tuple[Figure, float]:
        """The figure saved last to a file named `name`, and its dpi."""
        found = [(f, dpi) for f, p, dpi in self.saved if p.name == name]
        assert found, f"{name} not saved; saved: {[p.name for _, p, _ in self.saved]}"
        return found[-1]


def _drawn_texts(fig: Figure, dpi: float) -> tuple[list[Text], object]:
    """The texts drawn when `fig` is rendered at `dpi` (visible, not blank), and the renderer."""
    drawn: list[Text] = []
    original = Text.draw

    def draw(text, renderer):
        if text.get_visible() and text.get_text().strip():
            drawn.append(text)
        return original(text, renderer)

    fig.set_dpi(dpi)
    canvas = FigureCanvasAgg(fig)
    Text.draw = draw  # type: ignore[method-assign]
    try:
        canvas.draw()
    finally:
        Text.draw = original  # type: ignore[method-assign]
    return list(dict.fromkeys(drawn)), canvas.get_renderer()


def _where(text: Text) -> str:
    return repr(text.get_text()[:40])


def small_text(texts: list[Text], dpi: float) -> list[str]:
    """Texts smaller than `MIN_PT` at 100 % on a `SCREEN_DPI` screen."""
    return [
        f"text {_where(t)}: {t.get_fontsize() * dpi / SCREEN_DPI:.1f} pt on screen < {MIN_PT:g}"
        for t in texts
        if t.get_fontsize() * dpi / SCREEN_DPI < MIN_PT - 1e-9
    ]


def outside(texts: list[Text], fig: Figure, renderer) -> list[str]:
    """Texts whose rendered extent leaves the figure."""
    box = fig.bbox
    out = []
    for t in texts:
        e = t.get_window_extent(renderer)
        if (
            e.x0 < box.x0 - SLACK_PX
            or e.y0 < box.y0 - SLACK_PX
            or e.x1 > box.x1 + SLACK_PX
            or e.y1 > box.y1 + SLACK_PX
        ):
            out.append(f"text {_where(t)} outside the figure: {e.bounds} not in {box.bounds}")
    return out


def _labels(fig: Figure) -> set[Text]:
    """The axis labels of every axes of `fig` (colourbars' included)."""
    return {
        a.label
        for ax in fig.findobj(match=Axes)
        for a in (ax.xaxis, ax.yaxis)  # type: ignore
    }


def upside_down(texts: list[Text], fig: Figure) -> list[str]:
    """Texts at an angle a reader cannot read upright."""
    labels = _labels(fig)
    out = []
    for t in texts:
        angle = (t.get_rotation() + 180.0) % 360.0 - 180.0  # (-180, 180]
        angle = 180.0 if angle == -180.0 else angle
        upright = -90.0 < angle <= 90.0 or (t in labels and abs(angle + 90.0) < 1e-6)
        if not upright:
            out.append(f"text {_where(t)} at {angle:g} degrees reads upside down")
    return out


_NOT_IN_NUMBERS = re.compile(r"[$\\{}]|mathdefault")


def _is_number(label: str) -> bool:
    r"""A tick label shows a number ('0.5', '−12', '$\mathdefault{10^{-2}}$', '20 %')."""
    text = _NOT_IN_NUMBERS.sub("", label).replace("−", "-").replace("^", "e").rstrip(" %")
    try:
        float(text)
    except ValueError:
        return False
    return True


def missing_units(fig: Figure, texts: list[Text]) -> list[str]:
    """Axes that draw numeric tick labels without a label holding a unit in brackets."""
    drawn = set(texts)
    out = []
    for ax in fig.findobj(match=Axes):
        for name, axis in (("x", ax.xaxis), ("y", ax.yaxis)):
            ticks = [
                label
                for tick in axis.get_major_ticks() + axis.get_minor_ticks()
                for label in (tick.label1, tick.label2)
            ]
            shown = [t for t in ticks if t in drawn]
            if not any(_is_number(t.get_text()) for t in shown):
                continue  # no tick labels, or names (categories, unit ids)
            label = axis.label.get_text() if axis.label in drawn else ""
            if not UNIT.search(label):
                out.append(
                    f"{name} axis of {ax.get_title()[:40] or ax.get_label() or 'an axes'!r}: "
                    f"label {label!r} has no [unit]"
                )
    return out


def _series(ax: Axes) -> list:
    """The labelled series of `ax`: lines, collections and patches whose label is public."""
    artists = [*ax.lines, *ax.collections, *ax.patches]
    return [
        a
        for a in artists
        if isinstance(a, (Line2D, Collection, Patch))
        and a.get_visible()
        and str(a.get_label())
        and not str(a.get_label()).startswith("_")
    ]


def unexplained_series(fig: Figure) -> list[str]:
    """Labelled series named in no legend and shown by no colourbar."""
    legends = [lg for lg in fig.findobj(match=lambda a: type(a).__name__ == "Legend")]
    named = {t.get_text() for lg in legends for t in lg.get_texts()}
    mappables = {
        id(ax._colorbar.mappable)  # noqa: SLF001 (the colourbar of a colourbar axes)
        for ax in fig.findobj(match=Axes)
        if getattr(ax, "_colorbar", None) is not None
    }
    out = []
    for ax in fig.findobj(match=Axes):
        for a in _series(ax):
            if a.get_label() not in named and id(a) not in mappables:
                out.append(f"series {a.get_label()!r} ({type(a).__name__}) in no legend")
    return list(dict.fromkeys(out))


def figure_problems(fig: Figure, dpi: float) -> list[str]:
    """Every rule of the module `fig` saved at `dpi` breaks, one line each (none: readable)."""
    texts, renderer = _drawn_texts(fig, dpi)
    return [
        *small_text(texts, dpi),
        *outside(texts, fig, renderer),
        *upside_down(texts, fig),
        *missing_units(fig, texts),
        *unexplained_series(fig),
    ]
