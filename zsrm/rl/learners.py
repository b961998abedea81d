"""``zsrm train``'s entry: the learner a run's config names (``learner``) trains it.

ppo (:func:`zsrm.rl.ppo.train`, the default) or sac (:func:`zsrm.rl.sac.train_sac`); the random
baseline is PPO's (it trains nothing). Both write the same run folder.
"""
from __future__ import annotations

from pathlib import Path

from zsrm.rl.config import TrainConfig


def train(cfg: TrainConfig, out: str | Path, fresh: bool = False, progress: bool = True, on_eval=None,
          device: str = "cpu", env_workers: int = 1, shared_keypoints: str | Path | None = None) -> dict:
    """Train (or resume) one run with its learner; the summary (``out/summary.json``). The
    arguments are :func:`zsrm.rl.ppo.train`'s; ``shared_keypoints``: a folder where SAC runs that
    differ only in their reward share their keypoints' pretraining (:func:`zsrm.rl.pretrain.pretrain_keypoints`)."""
    import zsrm.rl.ppo as ppo

    if cfg.learner == "ppo" or cfg.reward == "random":
        return ppo.train(cfg, out, fresh, progress, on_eval, device, env_workers)
    from zsrm.rl.sac import train_sac

    out = Path(out)
    if (summary := ppo.finished(cfg, out, fresh)) is not None:
        return summary
    return train_sac(cfg, out, fresh, progress, on_eval, ppo.resolve_device(device), int(env_workers),
                     None if shared_keypoints is None else Path(shared_keypoints))
