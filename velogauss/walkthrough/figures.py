"""Figures of the walkthrough: matplotlib's Agg canvas, one PNG per figure, atomic writes.

Figures are built on `matplotlib.figure.Figure` with an Agg canvas, never through pyplot,
so generating them neither needs a display nor changes the caller's global backend.
"""

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Ellipse

from velogauss_core.motion import COLUMN_GROUPS
from velogauss.io_utils import atomic_path

DPI = 110
# One colour family per basis group (VG-BASIS), three shades each, so a curve's colour says
# which kind of motion it is: translation blues, rotation reds, stretch greens, shear purples.
_FAMILIES = {"translation": ("#08519c", "#3182bd", "#6baed6"), "rotation": ("#a50f15", "#de2d26", "#fb6a4a"),
             "stretch": ("#006d2c", "#31a354", "#74c476"), "shear": ("#54278f", "#756bb1", "#9e9ac8")}


def _column_styles():
    """(colour, label) of each of the 12 basis columns, label `wK (group)` as in spec/motion.md."""
    styles = [None] * 12
    for group, columns in COLUMN_GROUPS.items():
        for column, colour in zip(columns, _FAMILIES[group]):
            styles[column] = (colour, f"w{column + 1} ({group})")
    return styles


COLUMN_COLOURS, COLUMN_LABELS = (list(x) for x in zip(*_column_styles()))


def new_figure(width, height):
    """An empty figure of `width` x `height` inches on an Agg canvas, constrained layout."""
    fig = Figure(figsize=(width, height), layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def save(fig, folder, name, caption):
    """Write `fig` to folder/name.png; return its Markdown: the image and its caption."""
    with atomic_path(folder / f"{name}.png") as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    emphasised = caption.replace("*", r"\*")  # a literal * (x*(t)) would end the italics
    return f"![{name}](figures/{name}.png)\n\n*{emphasised}*"


def covariance_ellipse(ax, centre, cov, n_sigma=1.0, **style):
    """Draw the n_sigma contour of the 2D Gaussian with covariance `cov` (2, 2) at `centre`."""
    eigenvalues, eigenvectors = np.linalg.eigh(cov)
    angle = np.degrees(np.arctan2(eigenvectors[1, 1], eigenvectors[0, 1]))  # major axis direction
    width, height = 2 * n_sigma * np.sqrt(eigenvalues[::-1])
    ax.add_patch(Ellipse(centre, width, height, angle=angle, fill=False, **style))
