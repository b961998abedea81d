"""``zsrm eval-vlm``: the scene VLM's zero-shot object presence on held-out renders.

For every image and colour c the probe is "a c block" (or "a c puck" in the pushing scene);
the score is its cosine similarity minus the mean similarity of the other colours' probes
(a relative score, as CLIP's zero-shot classifiers compare classes, which removes how
"similar to everything" an image is). AUROC of that score against whether c's object is
visible gives one number per colour.

Truth comes from MuJoCo's segmentation: visible means at least ``MIN_VISIBLE_PIXELS`` pixels
(at 64 px). Objects showing 1 to ``MIN_VISIBLE_PIXELS - 1`` pixels are neither clearly present
nor absent; they are left out of that colour's AUROC and counted in the meta.
"""
from __future__ import annotations

import math
import platform
from pathlib import Path

from zsrm.common.files import write_json
from zsrm.data.renders import SCENES, render_presence_scenes
from zsrm.evaluation.metrics import auroc
from zsrm.evaluation.plots import pyplot, save_figure
from zsrm.tasks.language import COLOURS
from zsrm.tasks.relations import CAMERAS
from zsrm.vlm.base import VisionLanguageModel
from zsrm.vlm.presence import min_visible_pixels, presence_scores


def presence_eval(vlm: VisionLanguageModel, n_images: int = 500, seed: int = 0, image_size: int = 64,
                  progress: bool = True) -> tuple[dict, dict]:
    """Render ``n_images`` held-out images (eval seed stream) and score presence.

    Returns (result JSON dict, arrays for plotting).
    """
    from tqdm import tqdm

    n_scenes = math.ceil(n_images / len(CAMERAS))
    with tqdm(total=n_scenes, desc="render held-out scenes", unit="scene", disable=not progress) as bar:
        data = render_presence_scenes(range(n_scenes), seed=seed, stream="eval", size=image_size, progress=bar.update)
    data = {k: v[:n_images] for k, v in data.items()}
    scores, sims = presence_scores(vlm, data["images"], data["shape"])
    threshold = min_visible_pixels(image_size)
    present = data["visible"] >= threshold
    absent = data["visible"] == 0
    used = present | absent

    result: dict = {}
    raw, by_camera, by_scene, counts = {}, {}, {}, {}
    for j, c in enumerate(COLOURS):
        m = used[:, j]
        result[f"auroc.{c}"] = round(auroc(scores[m, j], present[m, j]), 4)
        raw[c] = round(auroc(sims[m, j], present[m, j]), 4)
        by_camera[c] = {cam: round(auroc(scores[m & (data["camera"] == k), j], present[m & (data["camera"] == k), j]), 4)
                        for k, cam in enumerate(CAMERAS)}
        by_scene[c] = {s: round(auroc(scores[m & (data["shape"] == k), j], present[m & (data["shape"] == k), j]), 4)
                       for k, s in enumerate(SCENES)}
        counts[c] = {"present": int(present[:, j].sum()), "absent": int(absent[:, j].sum()),
                     "left_out_partly_visible": int((~used[:, j]).sum())}
    result["meta"] = {
        "n_images": int(n_images),
        "n_scenes": int(n_scenes),
        "cameras": list(CAMERAS),
        "scenes": {s: int((data["shape"] == k).sum()) for k, s in enumerate(SCENES)},
        "image_size": image_size,
        "seed": seed,
        "held_out": "eval seed stream (numpy SeedSequence [1, seed, scene]); training renders use [0, seed, scene]",
        "score": "cos(image, 'a C block|puck') minus the mean cos of the other three colours' probes",
        "truth": f"object visible with >= {threshold} pixels (MuJoCo segmentation); 1-{threshold - 1} px left out",
        "counts": counts,
        "auroc_raw_cosine": raw,
        "auroc_by_camera": by_camera,
        "auroc_by_scene": by_scene,
        "vlm": getattr(vlm, "meta", {}) if vlm.backend == "scene" else {"pretrained": getattr(vlm, "pretrained", None)},
        "machine": platform.platform(),
    }
    return result, {"scores": scores, "present": present, "used": used}


def own_presence_eval(vlm: VisionLanguageModel, scene: str, n_images: int = 500, seed: int = 0,
                      image_size: int = 64, progress: bool = True) -> tuple[dict, dict]:
    """:func:`presence_eval` on held-out renders of a user's own scene (``scene``: its adapter,
    ``module:Class`` or a registered id): per object, AUROC of its phrase's probe ("a red mug")
    scored against the other objects' probes, against whether it is visible. Truth, as for
    zsrm's scenes, from the simulator (the adapter's privileged accessor and segmentation)."""
    import torch
    from tqdm import tqdm

    from zsrm.data.own_renders import render_own_scenes
    from zsrm.envs.adapter import ROLES, load_adapter
    from zsrm.vlm.presence import phrase_probe

    adapter = load_adapter(scene)
    objects, n_scenes = tuple(adapter.objects), math.ceil(n_images / len(ROLES))
    with tqdm(total=n_scenes, desc="render held-out scenes", unit="scene", disable=not progress) as bar:
        data = render_own_scenes(adapter, range(n_scenes), seed=seed, stream="eval", size=image_size,
                                 progress=bar.update)
    data = {k: v[:n_images] for k, v in data.items()}
    with torch.no_grad():
        probes = vlm.encode_texts([phrase_probe(p) for p in objects])
        sims = torch.cat([vlm.encode_images(data["images"][lo:lo + 256]) @ probes.T
                          for lo in range(0, len(data["images"]), 256)]).cpu().numpy()
    scores = sims - (sims.sum(axis=1, keepdims=True) - sims) / max(1, len(objects) - 1)
    present, absent = data["visible"] >= min_visible_pixels(image_size), data["visible"] == 0
    used = present | absent
    # An object shown in every render (or in none) has no AUROC: say so rather than NaN.
    unmeasured = {p: "present in every render" if not absent[:, j].any() else "absent from every render"
                  for j, p in enumerate(objects) if not (present[:, j].any() and absent[:, j].any())}
    result: dict = {f"auroc.{p}": None if p in unmeasured else round(auroc(scores[used[:, j], j], present[used[:, j], j]), 4)
                    for j, p in enumerate(objects)}
    result["meta"] = {
        "scene": adapter.name, "objects": list(objects), "n_images": int(n_images), "n_scenes": int(n_scenes),
        "cameras": dict(adapter.roles), "image_size": image_size, "seed": seed,
        "held_out": "the own scene's eval seed stream; training renders use its train stream",
        "score": "cos(image, 'a PHRASE') minus the mean cos of the other objects' probes",
        "counts": {p: {"present": int(present[:, j].sum()), "absent": int(absent[:, j].sum())}
                   for j, p in enumerate(objects)},
        "unmeasured": unmeasured,
        "vlm": getattr(vlm, "meta", {}) if vlm.backend == "scene" else {"pretrained": getattr(vlm, "pretrained", None)},
        "machine": platform.platform(),
    }
    return result, {"scores": scores, "present": present, "used": used}


def plot_presence(arrays: dict, result: dict, path: Path) -> Path:
    """ROC curves per colour (left) and score histograms, present against absent (right)."""
    plt = pyplot()
    from sklearn.metrics import roc_curve

    colours = {"red": "#d62728", "green": "#2ca02c", "yellow": "#e6b800", "blue": "#1f77b4"}
    names = result["meta"].get("objects") or COLOURS  # an own scene's phrases, or the colours
    fig, (ax_roc, ax_hist) = plt.subplots(1, 2, figsize=(10, 4.2))
    for j, c in enumerate(names):
        m, colour = arrays["used"][:, j], colours.get(c, colours.get(c.split()[0], f"C{j}"))
        truth, score = arrays["present"][m, j], arrays["scores"][m, j]
        if truth.any() and not truth.all():
            fpr, tpr, _ = roc_curve(truth, score)
            ax_roc.plot(fpr, tpr, color=colour, label=f"{c}: AUROC {result[f'auroc.{c}']:.3f}")
        ax_hist.hist(score[truth], bins=30, alpha=0.45, color=colour, histtype="stepfilled")
        ax_hist.hist(score[~truth], bins=30, color=colour, histtype="step", linestyle="--")
    ax_roc.plot([0, 1], [0, 1], color="grey", lw=0.8, ls=":")
    ax_roc.set(xlabel="false positive rate", ylabel="true positive rate", title="zero-shot presence (ROC)")
    ax_roc.legend(loc="lower right")
    ax_hist.set(xlabel="score: cos(probe) - mean cos(the other probes)", ylabel="images",
                title="filled: object visible, dashed: absent")
    n, scene = result["meta"]["n_images"], result["meta"].get("scene")
    fig.suptitle(f"scene VLM presence probes on {n} held-out renders (3 cameras, "
                 f"{'of ' + scene if scene else 'blocks and pucks'})", fontsize=10)
    return save_figure(fig, path)


def write_presence_results(result: dict, arrays: dict, out: Path) -> tuple[Path, Path]:
    out = write_json(out, result)
    png = plot_presence(arrays, result, out.with_suffix(".png"))
    return out, png
