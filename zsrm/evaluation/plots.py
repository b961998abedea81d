"""What every figure of zsrm shares: drawn off screen, written as PNG the same way."""
from __future__ import annotations

from pathlib import Path


def pyplot():
    """matplotlib's pyplot on the off-screen Agg backend (no display on the machines zsrm runs on)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, dpi: int = 120) -> Path:
    """Lay out ``fig``, write it to ``path`` (parent folders made) and close it."""
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    pyplot().close(fig)
    return path
