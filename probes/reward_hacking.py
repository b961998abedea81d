"""Where a policy trained with the zsrm reward collects reward the oracle does not give.

Rolls out a saved policy (``zsrm train``) on seeded evaluation episodes and scores every
decision with both the zsrm reward (the policy's own training reward) and the oracle. For the
frames where they disagree it reports the goal objects' offset in the camera plane the
relation is read on (metres: x right, y up for the front camera), beside Table 1's thresholds,
so a reward the policy exploits shows as a geometry the oracle rejects (a block held too high
to be "on top of", say), and the first object's height above the table (a block held in the air
beside the others, where a student read "in between").

    python probes/reward_hacking.py runs/rl/stack-zsrm-0/policy --episodes 20 \
        --out results/rl/reward_hacking_stack.json
"""
from __future__ import annotations

import argparse
from dataclasses import asdict, replace

import numpy as np

from zsrm.common.files import write_json
from zsrm.envs.base import TABLE_TOP
from zsrm.rewards import RewardModel, VecZeroShotReward
from zsrm.rl.envs import make_reward, make_vec
from zsrm.rl.evaluate import eval_seed
from zsrm.rl.features import policy_view
from zsrm.rl.goals import task_entry
from zsrm.rl.policy import PolicyBundle
from zsrm.tasks.relations import RELATIONS, WORLD_THRESHOLDS, camera_plane
from zsrm.vlm import load_vlm


class FrameTap(RewardModel):
    """A reward model that keeps every batch of frames it scores (the goal camera's)."""

    def __init__(self, inner: RewardModel):
        self.inner, self.name, self.frames = inner, inner.name, []

    def prepare(self, goal: str) -> None:
        self.inner.prepare(goal)

    def compute(self, observations, goal, infos):
        self.frames.append(np.array(observations[self.inner.goal_camera(goal)]))
        return self.inner(observations, goal, infos)


def score_rollouts(policy: str, episodes: int, reward_model: str | None = None,
                   labeler: str | None = None) -> dict[str, np.ndarray]:
    """Per decision: the zsrm reward (of ``reward_model``, default the one the policy trained
    with), the oracle's verdict, the goal objects' plane offset and the first one's height; with
    ``labeler`` (a folder for its calibration renders), the goal labeler's verdict too
    (:class:`zsrm.grounding.goal_check.GoalLabeler`, what ``--zsrm-correct-every`` trains on)."""
    bundle = PolicyBundle.load(policy)
    cfg = bundle.cfg
    entry = task_entry(cfg.goal)
    task = entry.task
    scorer = replace(cfg, reward="zsrm", reward_model=reward_model or cfg.reward_model, zsrm_correct_every=0)
    tap = FrameTap(make_reward(scorer))
    venv = VecZeroShotReward(make_vec(cfg, episodes, eval_seed(cfg.seed)), tap, entry.goal)
    venv = policy_view(venv, load_vlm(cfg.vlm), cfg)
    camera = RELATIONS[task.relation].camera
    obs, rows, running, kept = venv.reset(), [], np.ones(episodes, dtype=bool), []
    while running.any():
        obs, rewards, dones, infos = venv.step(bundle.act(obs, deterministic=cfg.eval_deterministic))
        for i, info in enumerate(infos):
            if running[i]:
                positions = info["object_positions"]
                a, b = (camera_plane(positions[c], camera) for c in task.objects[:2])
                rows.append((rewards[i], info["is_success"], *(a - b), positions[task.objects[0]][2] - TABLE_TOP))
                kept.append(tap.frames[-1][i])
                running[i] = not dones[i]
    venv.close()
    zsrm, oracle, dx, dy, height = np.array(rows, dtype=np.float64).T
    out = {"zsrm": zsrm > 0.5, "oracle": oracle > 0.5, "dx": dx, "dy": dy, "height": height}
    if labeler:
        from zsrm.rl.corrected import goal_labeler

        out["labeler"] = goal_labeler(cfg, labeler)(np.stack(kept))
    return out


def summarise(frames: dict[str, np.ndarray]) -> dict:
    def offsets(mask):
        if not mask.any():
            return {"frames": 0}
        return {"frames": int(mask.sum()), "median_abs_dx_m": float(np.median(np.abs(frames["dx"][mask]))),
                "median_dy_m": float(np.median(frames["dy"][mask])),
                "p90_dy_m": float(np.percentile(frames["dy"][mask], 90)),
                "median_height_m": float(np.median(frames["height"][mask]))}

    z, o = frames["zsrm"], frames["oracle"]
    out = {"decisions": int(z.size), "zsrm_rate": float(z.mean()), "oracle_rate": float(o.mean()),
           "both": offsets(z & o), "zsrm_only": offsets(z & ~o), "oracle_only": offsets(~z & o),
           "neither": offsets(~z & ~o)}
    if "labeler" in frames:
        lab = frames["labeler"]
        out["labeler"] = {"rate": float(lab.mean()), "agrees_with_oracle": float((lab == o).mean()),
                          "zsrm_agrees_with_oracle": float((z == o).mean()),
                          "says_goal_on_zsrm_only": float(lab[z & ~o].mean()) if (z & ~o).any() else None,
                          "recall_of_oracle_goal": float(lab[o].mean()) if o.any() else None}
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("policy", help="a policy folder written by zsrm train")
    parser.add_argument("--episodes", type=int, default=20)
    parser.add_argument("--reward-model", help="score with this zsrm model folder instead of the policy's own")
    parser.add_argument("--labeler", metavar="FOLDER",
                        help="also ask the goal labeler (Grad-CAM + Table 1), calibrated on renders kept in FOLDER")
    parser.add_argument("--out", default="results/rl/reward_hacking.json")
    args = parser.parse_args()
    summary = summarise(score_rollouts(args.policy, args.episodes, args.reward_model, args.labeler))
    summary["meta"] = {"policy": args.policy, "episodes": args.episodes, "thresholds": asdict(WORLD_THRESHOLDS),
                       "reward_model": args.reward_model or "the policy's own",
                       "offset": "first goal object minus second, in the plane of the camera the relation is "
                                 "read on (metres)",
                       "height": "the first goal object's centre above the table (metres; a block resting "
                                 "on it: 0.03)",
                       "command": f"python probes/reward_hacking.py {args.policy} --episodes {args.episodes} "
                                  + (f"--reward-model {args.reward_model} " if args.reward_model else "")
                                  + (f"--labeler {args.labeler} " if args.labeler else "")
                                  + f"--out {args.out}"}
    write_json(args.out, summary)
    for key in ("both", "zsrm_only", "oracle_only", "labeler"):
        print(key, summary.get(key))
    print(f"zsrm says yes on {summary['zsrm_rate']:.2f} of decisions, the oracle on {summary['oracle_rate']:.2f}; "
          f"wrote {args.out}")


if __name__ == "__main__":
    main()
