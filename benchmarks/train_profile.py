"""Where ``zsrm train``'s time goes, and what each speed lever bought: a ladder of configurations
from v1 (the configuration of the results committed before 2026-12-04) to the default, one
lever added per rung, each profiled part by part.

Each rung runs :func:`zsrm.rl.ppo.train` itself (rollouts, reward, PPO update, auxiliary loss,
evaluation and checkpoints every 20k env steps, the final evaluation) with the zsrm reward (the
shipped student), with timers around its parts (exclusive time: a part's time excludes the
parts timed inside it), reported as seconds per 10k env steps:

* ``scenes`` physics and SB3's VecEnv (``rendering`` apart), ``vlm_trunk`` the frozen VLM
  trunk on each frame, ``reward`` the reward model, ``policy_forward`` the policy's action
  during rollouts, ``rollout_other`` SB3's rollout bookkeeping;
* ``update`` PPO's epochs in the loop; apart, ``update_by_network`` splits it per network
  (``<network>/forward`` and ``/backward``, each network alone on the run's own last rollout
  buffer, minibatch by minibatch as PPO does, scaled to the run's updates);
* ``inverse_dynamics`` (the keypoints' auxiliary loss), ``curiosity`` (ICM's reward and update,
  ``--reward curiosity`` only), ``evaluation`` and ``checkpoint``.

Levers in the code, which every rung has, are timed against the simple way beside them
(``micro``): the spatial softmax, the keypoints' 1x1 convs, the VLM trunk at 32 px, and
``torch.compile`` of the keypoint extractor (measured, not used: see ``note``).

    python benchmarks/train_profile.py --out results/rl/profile.json
"""
from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from collections import defaultdict
from contextlib import contextmanager

os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("HF_HUB_OFFLINE", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

from zsrm.common.files import write_json  # noqa: E402

# v1 to v2, one lever a rung (each rung's settings on top of the rungs before it); the default
# since (v3) changed the action noise and the evaluation, not what a step costs
LADDER = (
    ("v1", {}),
    ("32 px policy views", {"trunk_size": 32, "pixel_size": 32}),
    ("action repeat 4 (gamma, lambda per decision to match)", {"action_repeat": 4, "gamma": 0.96, "gae_lambda": 0.9}),
    ("16 envs x 32 steps, 4 epochs of minibatch 32", {"n_envs": 16, "n_steps": 32, "n_epochs": 4, "batch_size": 32}),
    ("learning rate annealed to 0 (v2)", {"anneal_lr": True}),
)

# Parts that start their own branch of the tree: their inner parts are theirs.
ROOTS = ("evaluation", "checkpoint", "inverse_dynamics", "curiosity_update")


class Timers:
    """Exclusive wall time per part, keyed by the root part it ran under."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)
        self.stack: list[list] = []  # [key, start, time of timed children]
        self.patches: list[tuple] = []

    @contextmanager
    def part(self, name: str):
        root = next((frame[0].split("/")[0] for frame in reversed(self.stack)
                     if frame[0].split("/")[0] in ROOTS), None)
        key = name if root is None or name in ROOTS else f"{root}/{name}"
        frame = [key, time.perf_counter(), 0.0]
        self.stack.append(frame)
        try:
            yield
        finally:
            self.stack.pop()
            elapsed = time.perf_counter() - frame[1]
            self.seconds[key] += elapsed - frame[2]
            if self.stack:
                self.stack[-1][2] += elapsed

    def wrap(self, owner, attr: str, name: str):
        original = getattr(owner, attr)
        timers = self

        def timed(*args, **kwargs):
            with timers.part(name):
                return original(*args, **kwargs)

        setattr(owner, attr, timed)
        self.patches.append((owner, attr, original))

    def restore(self):
        for owner, attr, original in reversed(self.patches):
            setattr(owner, attr, original)
        self.patches.clear()


def instrument(timers: Timers):
    """Timers around the parts of the training loop (patched on their classes and modules)."""
    import zsrm.envs.base as envs_base
    import zsrm.rl.ppo as ppo
    from stable_baselines3 import PPO
    from stable_baselines3.common.policies import ActorCriticPolicy
    from stable_baselines3.common.vec_env import DummyVecEnv
    from zsrm.rewards import VecZeroShotReward
    from zsrm.rl.auxiliary import InverseDynamicsAux
    from zsrm.rl.curiosity import ICMUpdate, VecCuriosity
    from zsrm.rl.features import VecImageFeatures

    timers.wrap(PPO, "collect_rollouts", "rollout_other")
    timers.wrap(PPO, "train", "update")
    timers.wrap(DummyVecEnv, "step_wait", "scenes")
    timers.wrap(DummyVecEnv, "reset", "scenes")
    timers.wrap(envs_base.MujocoPixelEnv, "_render_camera", "rendering")
    timers.wrap(VecZeroShotReward, "step_wait", "reward")
    timers.wrap(VecImageFeatures, "step_wait", "vlm_trunk")
    timers.wrap(VecImageFeatures, "reset", "vlm_trunk")
    timers.wrap(ActorCriticPolicy, "forward", "policy_forward")
    timers.wrap(ActorCriticPolicy, "predict", "policy_forward")
    timers.wrap(InverseDynamicsAux, "_on_rollout_end", "inverse_dynamics")
    timers.wrap(VecCuriosity, "step_wait", "curiosity_reward")
    timers.wrap(ICMUpdate, "_on_rollout_end", "curiosity_update")
    timers.wrap(ppo.Evaluator, "__call__", "evaluation")
    timers.wrap(ppo, "save_checkpoint", "checkpoint")
    timers.wrap(ppo.PolicyBundle, "save", "checkpoint")
    # keep the last model and rollout buffer for the per-network split of the update
    kept = {}
    original_train = PPO.train

    def train_and_keep(self, *args, **kwargs):
        kept["model"] = self
        kept["updates"] = kept.get("updates", 0) + 1
        return original_train(self, *args, **kwargs)

    PPO.train = train_and_keep
    timers.patches.append((PPO, "train", original_train))
    return kept


def networks(policy) -> list[tuple[str, torch.nn.Module, callable]]:
    """The policy's networks in the order the update runs them: (name, module, input from the previous output)."""
    from zsrm.rl.features import FEATURES_KEY, IMAGE_KEY

    extractor = policy.features_extractor
    parts = [("vlm_keypoints", lambda obs, _: extractor.softmax(extractor.heat_maps(obs[FEATURES_KEY])))]
    if extractor.pixels is not None:
        parts.append(("pixel_cnn", lambda obs, _: extractor.pixels(obs[IMAGE_KEY])))

    def heads(obs, points):
        latent_pi, latent_vf = policy.mlp_extractor(extractor.out(points))
        distribution = policy._get_action_dist_from_latent(latent_pi)
        actions = distribution.get_actions()
        return torch.cat([distribution.log_prob(actions)[:, None], policy.value_net(latent_vf)], dim=1)

    parts.append(("heads", heads))
    return parts


def update_split(model, updates: int, repeats: int = 3) -> dict[str, float]:
    """Forward and backward seconds of each network over ``updates`` PPO updates, timed on the
    model's last rollout buffer with the update's minibatch size and epochs."""
    policy, buffer = model.policy, model.rollout_buffer
    batches = list(buffer.get(model.batch_size))
    per_update = model.n_epochs * len(batches)
    seconds = defaultdict(float)
    timed = 0
    for _ in range(repeats):
        for batch in batches:
            obs = batch.observations
            inputs, outputs = [], []
            for name, fn in networks(policy):
                t = time.perf_counter()
                # each network's input is the detached output of those before it, so its backward is its own
                points = torch.cat([o.detach().requires_grad_() for o in outputs], dim=1) if outputs else None
                if name == "heads":
                    inputs.append(points)
                    out = fn(obs, points)
                else:
                    out = fn(obs, None)
                seconds[f"{name}/forward"] += time.perf_counter() - t
                outputs.append(out) if name != "heads" else None
                t = time.perf_counter()
                out.sum().backward(retain_graph=name != "heads")
                seconds[f"{name}/backward"] += time.perf_counter() - t
            policy.zero_grad(set_to_none=True)
            timed += 1
    return {k: v / timed * per_update * updates for k, v in seconds.items()}


def profile(settings: dict, reward: str, steps: int, goal: str) -> dict:
    """Train ``steps`` env steps of TrainConfig ``settings`` under the timers."""
    from zsrm.rl.config import TrainConfig
    from zsrm.rl.ppo import train

    cfg = TrainConfig(**{**settings, "goal": goal, "reward": reward, "steps": steps})
    timers = Timers()
    kept = instrument(timers)
    try:
        with tempfile.TemporaryDirectory() as out:
            t = time.perf_counter()
            summary = train(cfg, out, progress=False)
            wall = time.perf_counter() - t
    finally:
        timers.restore()
    env_steps = summary["env_steps"]
    parts = dict(timers.seconds)
    update = parts.pop("update", 0.0)
    split = update_split(kept["model"], kept["updates"])
    parts["update"] = update
    parts["setup_and_untimed"] = wall - sum(timers.seconds.values())  # loading models, building envs, the rest

    def per_10k(values: dict) -> dict:
        return {k: round(v / env_steps * 10_000, 3) for k, v in sorted(values.items())}

    return {"reward": reward, "goal": goal, "env_steps": env_steps, "wall_s": round(wall, 1),
            "env_steps_per_s": round(env_steps / wall, 1), "seconds_per_10k_env_steps": per_10k(parts),
            "update_by_network_per_10k_env_steps": per_10k(split), "ppo_updates": kept["updates"],
            "train_config": cfg.to_dict()}


def ladder_settings() -> list[tuple[str, dict]]:
    """Each rung's TrainConfig settings: v1's, then each lever added."""
    from zsrm.rl.config import PRESETS

    settings, rungs = dict(PRESETS["v1"]), []
    for name, lever in LADDER:
        settings = {**settings, **lever}
        rungs.append((name, dict(settings)))
    return rungs


def old_spatial_softmax(softmax, maps: torch.Tensor) -> torch.Tensor:
    """SpatialSoftmax.forward as it was in v1 (std computed twice), the simple way."""
    flat = maps.flatten(2)
    peak = (flat.amax(dim=-1) - flat.mean(dim=-1)) / (flat.std(dim=-1) + 1e-6)
    standard = (flat - flat.mean(dim=-1, keepdim=True)) / (flat.std(dim=-1, keepdim=True) + 1e-6)
    attention = torch.softmax(standard / softmax.log_temperature.exp(), dim=-1)
    return torch.cat([(attention @ softmax.grid).flatten(1), peak / 4.0], dim=1)


def old_shrink_frames(images: np.ndarray, side: int) -> np.ndarray:
    """The policy's frames as v1 shrank them (numpy's float64 block mean), the simple way."""
    n, size = images.shape[:2]
    k = size // side
    return np.ascontiguousarray(images.reshape(n, side, k, side, k, 3).mean(axis=(2, 4)).round()
                                .transpose(0, 3, 1, 2), dtype=np.uint8)


def per_call_ms(fn, repeats: int = 40) -> float:
    for _ in range(3):
        fn()
    t = time.perf_counter()
    for _ in range(repeats):
        fn()
    return (time.perf_counter() - t) / repeats * 1000


def micro(compile_extractor: bool) -> dict:
    """The code's levers against the simple way, on a minibatch of 32 (forward + backward)
    or a rollout step's 16 frames (the frozen trunk, forward only)."""
    import gymnasium as gym

    from zsrm.rl.features import KeypointExtractor
    from zsrm.vlm import load_vlm

    torch.manual_seed(0)
    space = gym.spaces.Dict({"features": gym.spaces.Box(0.0, np.inf, (128, 8, 8), np.float32),
                             "image": gym.spaces.Box(0, 255, (3, 32, 32), np.uint8)})
    extractor = KeypointExtractor(space)
    obs = {"features": torch.rand(32, 128, 8, 8), "image": torch.randint(0, 256, (32, 3, 32, 32), dtype=torch.uint8)}
    maps = torch.randn(32, 32, 8, 8, requires_grad=True)
    results = {}

    def pair(name, simple, fast):
        simple_ms, fast_ms = per_call_ms(simple), per_call_ms(fast)
        results[name] = {"simple_ms": round(simple_ms, 3), "fast_ms": round(fast_ms, 3),
                         "ratio": round(simple_ms / fast_ms, 2)}

    pair("spatial softmax (32 maps of 8x8, minibatch 32, forward + backward)",
         lambda: old_spatial_softmax(extractor.softmax, maps).sum().backward(),
         lambda: extractor.softmax(maps).sum().backward())
    pair("keypoint heat, two 1x1 convs on the 128x8x8 map (minibatch 32, forward + backward): Conv2d / matmul",
         lambda: extractor.heat(obs["features"]).sum().backward(),
         lambda: extractor.heat_maps(obs["features"]).sum().backward())
    vlm = load_vlm("scene")
    frames = vlm.preprocess(np.random.default_rng(0).integers(0, 256, (16, 64, 64, 3), dtype=np.uint8))
    small = torch.nn.functional.interpolate(frames, size=32, mode="area")
    with torch.no_grad():
        pair("frozen VLM trunk on 16 frames: 64 px / 32 px", lambda: vlm.image_trunk(frames),
             lambda: vlm.image_trunk(small))
    from zsrm.rl.features import shrink_frames
    from zsrm.vlm.base import pixels_from_images

    images = np.random.default_rng(1).integers(0, 256, (16, 64, 64, 3), dtype=np.uint8)
    pair("the pixel CNN's frames, 16 frames 64 -> 32 px: numpy float64 block mean / avg_pool2d (same bytes)",
         lambda: old_shrink_frames(images, 32), lambda: shrink_frames(images, 32))
    cfg = vlm.config
    pair("VLM preprocessing of a 16-frame batch: split into frames and stacked / read as one batch (same values)",
         lambda: pixels_from_images(list(images), cfg.image_size, cfg.mean, cfg.std),
         lambda: pixels_from_images(images, cfg.image_size, cfg.mean, cfg.std))
    if compile_extractor:
        t = time.perf_counter()
        compiled = torch.compile(extractor)
        compiled(obs).sum().backward()
        compile_s = time.perf_counter() - t
        pair("keypoint extractor (minibatch 32, forward + backward): eager / torch.compile",
             lambda: extractor(obs).sum().backward(), lambda: compiled(obs).sum().backward())
        results["keypoint extractor (minibatch 32, forward + backward): eager / torch.compile"]["compile_s"] = \
            round(compile_s, 1)
    return results


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rewards", nargs="+", default=["zsrm"], help="rewards to profile each rung with")
    parser.add_argument("--goal", default="stack")
    parser.add_argument("--steps", type=int, default=20_000, help="env steps per profiled run")
    parser.add_argument("--rungs", type=int, default=len(LADDER), help="profile the first N rungs of the ladder")
    parser.add_argument("--curiosity-steps", type=int, default=10_000,
                        help="also profile the curiosity reward (ICM) on the first and last rung, this many env steps")
    parser.add_argument("--no-compile", action="store_true", help="skip timing torch.compile (about 20 s to compile)")
    parser.add_argument("--out", default=None)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    runs = []
    rungs = ladder_settings()[:args.rungs]
    plan = [(name, settings, reward, args.steps) for name, settings in rungs for reward in args.rewards]
    if args.curiosity_steps:
        plan += [(name, settings, "curiosity", args.curiosity_steps) for name, settings in (rungs[0], rungs[-1])]
    for name, settings, reward, steps in plan:
        run = {"rung": name, **profile(settings, reward, steps, args.goal)}
        runs.append(run)
        print(f"{name}, {reward}: {run['env_steps_per_s']:.0f} env steps/s over {run['env_steps']} steps", flush=True)
        for k, v in run["seconds_per_10k_env_steps"].items():
            print(f"  {k:40s} {v:8.2f} s / 10k env steps")
    levers = micro(compile_extractor=not args.no_compile)
    for k, v in levers.items():
        print(f"{k}: {v['simple_ms']:.2f} ms -> {v['fast_ms']:.2f} ms ({v['ratio']:.2f}x)")
    result = {"runs": runs, "micro": levers, "meta": {
        "what": "seconds of each part of zsrm train per 10k env steps, exclusive times, for each rung of the "
                "ladder from v1 (before) to the default (after); update_by_network is timed apart on each run's "
                "last rollout buffer (forward and backward of each network alone, scaled to the run's updates), "
                "so its sum need not equal the in-loop update",
        "note": "torch.compile of the keypoint extractor is faster per call but costs its compile time in every "
                "run and on every new batch shape (rollout, minibatch, evaluation), so the default stays eager",
        "torch_threads": 1, "machine": f"{platform.machine()}, {os.cpu_count()} cores, no GPU",
        "command": "python benchmarks/train_profile.py"
                   + (f" --steps {args.steps}" if args.steps != 20_000 else "")
                   + (f" --rewards {' '.join(args.rewards)}" if args.rewards != ["zsrm"] else "")
                   + (f" --curiosity-steps {args.curiosity_steps}" if args.curiosity_steps != 10_000 else "")
                   + (f" --out {args.out}" if args.out else "")}}
    if args.out:
        write_json(args.out, result)
    return result


if __name__ == "__main__":
    main()
