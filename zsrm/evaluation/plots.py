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
    """Lay out ``fig``, write it to ``path`` atomically (parent folders made) and close it."""
    from zsrm.common.files import atomic_path

    try:
        fig.tight_layout()
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi)
    finally:
        pyplot().close(fig)
    return Path(path)
