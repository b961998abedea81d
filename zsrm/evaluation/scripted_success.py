"""``zsrm scripted-eval``: every task is achievable, shown by the true-state scripted controllers."""
from __future__ import annotations

from zsrm.envs.rollout import make_env, run_episode
from zsrm.envs.scripted import scripted_controller
from zsrm.tasks.catalogue import REPORT_TASKS


def scripted_success(tasks=REPORT_TASKS, episodes: int = 20, progress: bool = True) -> dict[str, float]:
    """Success rate of the scripted controller over seeded episodes (seeds 0..episodes-1)."""
    from tqdm import tqdm

    rates = {}
    for task in tasks:
        env = make_env(task)
        wins = sum(run_episode(env, scripted_controller, seed=seed)["success"]
                   for seed in tqdm(range(episodes), desc=f"scripted {task}", disable=not progress))
        rates[task] = wins / episodes
        env.close()
    return rates
