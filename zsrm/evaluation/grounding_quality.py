"""``zsrm eval-grounding``: how well Grad-CAM finds objects, and how right its captions are.

* localisation: pixel distance from each present object's Grad-CAM coordinates to its true
  projected centre, per camera (median, 90th percentile, in pixels and block widths), also
  for the paper's plain argmax of the stored heat maps;
* captions: precision / recall / F1 per relation of the Grad-CAM captions against the
  captions that the true pixel coordinates give under the same rules and thresholds (this
  isolates grounding errors), and against the world oracle (which adds the error of reading
  3-D relations off 2-D views);
* presence: how well the Grad-CAM target score tells a phrase for an object in the scene
  from one for an object that is not (AUROC);
* Figure 3: an image and the heat maps of "red block" and "yellow block", per camera.

In data collected with the box (``zsrm collect --p-box``) the box is a fifth object of the
captions (a block "inside of" it) and its localisation is reported apart (``*_box``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from zsrm.common.files import write_json, write_text
from zsrm.data.dataset import LABELS, ExplorationData
from zsrm.data.shards import load_npz, read_manifest
from zsrm.envs.cameras import apply_homography
from zsrm.evaluation.metrics import auroc
from zsrm.evaluation.plots import pyplot, save_figure
from zsrm.grounding.annotate import Grounder, LabelConfig, gradcam_objects, labelers, reads_solid, world_thresholds
from zsrm.grounding.gradcam import grid_centres, locate
from zsrm.grounding.labeler import RelationTable, relation_tuples, world_table
from zsrm.tasks.catalogue import SCENE_SHAPES
from zsrm.tasks.language import COLOURS
from zsrm.tasks.relations import RELATIONS

MIN_SUPPORT = 20  # fewer true positives than this: the F1 is reported but flagged as noisy


def load_labels(data: ExplorationData, labels: str | Path = LABELS) -> tuple[dict, dict]:
    """(labels manifest, concatenated label arrays) for the dataset's finished shards."""
    folder = data.labels_folder(labels)
    manifest = read_manifest(folder)
    missing = [s for s in data.shards if s not in manifest["shards"]]
    if missing:
        raise ValueError(f"{folder} has not labelled {len(missing)} shard(s) ({missing[0]}, ...): run zsrm label")
    parts = [load_npz(folder / f"{s}.npz") for s in data.shards]
    return manifest, {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def _errors(xy: np.ndarray, truth: np.ndarray, present: np.ndarray) -> np.ndarray:
    """Distances (N, 4) of located to true pixel coordinates; NaN for absent objects, inf for
    present objects that were not located."""
    err = np.linalg.norm(xy.astype(np.float64) - truth, axis=-1)
    err[present & ~np.isfinite(err)] = np.inf
    err[~present] = np.nan
    return err


def _summary(err: np.ndarray) -> dict:
    e = err[np.isfinite(err) | np.isinf(err)]
    if not len(e):
        return {"n": 0, "median": None, "p90": None}
    return {"n": int(len(e)), "median": float(np.median(e)), "p90": float(np.percentile(e, 90))}


def _wrong_object(xy: np.ndarray, truth: np.ndarray, present: np.ndarray) -> float:
    """Share of located objects whose Grad-CAM point is nearer another present object's true
    centre than its own."""
    d = np.linalg.norm(xy[:, :, None].astype(np.float64) - truth[:, None], axis=-1)  # (N, K, K)
    d[~np.broadcast_to(present[:, None, :], d.shape)] = np.inf
    ok = present & np.isfinite(xy).all(-1)
    nearest = np.argmin(d, axis=-1)
    return float((nearest != np.arange(present.shape[1])[None])[ok].mean()) if ok.any() else float("nan")


def prf(pred: RelationTable, truth: RelationTable) -> dict[str, dict]:
    """Precision, recall, F1 and support (true positives in ``truth``) per relation, over all
    (image, ordered object tuple) pairs. Undefined ratios are None."""
    out = {}
    for rel in pred.holds:
        p, t = pred.holds[rel], truth.holds[rel]
        tp, fp, fn = int((p & t).sum()), int((p & ~t).sum()), int((~p & t).sum())
        precision = tp / (tp + fp) if tp + fp else None
        recall = tp / (tp + fn) if tp + fn else None
        f1 = 2 * tp / (2 * tp + fp + fn) if tp + fp + fn else None
        out[rel] = {"precision": precision, "recall": recall, "f1": f1, "support": tp + fn, "predicted": tp + fp}
    return out


def _tables(data, cfg, pixels: dict, present, scene_index, world: bool = False, positions=None, axes=None):
    """Relation tables over all images (scenes' labelers applied to their own rows), over the
    data's objects (the colours, and the box where the data can hold it; an own scene's
    objects, its world table read along its role cameras' ``axes``)."""
    tuples = {r: relation_tuples(r, data.objects) for r in RELATIONS}
    holds = {r: np.zeros((len(present), len(tuples[r])), bool) for r in RELATIONS}
    for s, (scene, labeler) in enumerate(labelers(data, cfg).items()):
        rows = np.nonzero(scene_index == s)[0]
        if not len(rows):
            continue
        if world:
            table = world_table(positions[rows], present[rows], data.objects, world_thresholds(data, cfg), axes=axes,
                                solid=reads_solid(data, cfg))
        else:
            table = labeler.table({c: xy[rows] for c, xy in pixels.items()}, present[rows])
        for r in RELATIONS:
            holds[r][rows] = table.holds[r]
    return RelationTable(data.objects, tuples, holds)


def evaluate_grounding(data_folder, labels: str | Path = LABELS) -> dict:
    """The grounding report of a labelled dataset (see the module docstring)."""
    data = ExplorationData(data_folder)
    manifest, lab = load_labels(data, labels)
    cfg = LabelConfig(**manifest["config"])
    own = manifest.get("own_scene")  # an own scene's oracle axes and the labeler's notes
    if data.scene_adapter and own is None:
        raise ValueError(f"{data.labels_folder(labels)} was not labelled as an own scene's data: run zsrm label again")
    axes = own["oracle_axes"] if own else None
    arr = data.load(["positions", "present", "scene"] + [f"pixels_{c}" for c in data.cameras] + data.box_keys)
    scene_index = arr["scene"]
    scene0 = data.scenes[0]
    report = _localisation(data, lab, arr)
    if data.has_box:
        report.update(_box_localisation(data, lab, arr))
    # Captions relate the data's objects: the colours, and the box as a fifth where it can be.
    objects = data.object_arrays(arr)
    present = objects["present"]
    pixels = gradcam_objects(data, lab)
    truth_pixels = {c: objects[f"pixels_{c}"] for c in data.cameras}
    truth_table = _tables(data, cfg, truth_pixels, present, scene_index)
    world = _tables(data, cfg, None, present, scene_index, world=True, positions=objects["positions"], axes=axes)
    pred = _tables(data, cfg, pixels, present, scene_index)
    vs_pixel, vs_world = prf(pred, truth_table), prf(pred, world)
    for key, of in (("f1", "f1"), ("precision", "precision"), ("recall", "recall"), ("support", "support")):
        report[key] = {r: v[of] for r, v in vs_pixel.items()}
    report["f1_vs_world"] = {r: v["f1"] for r, v in vs_world.items()}
    report["support_world"] = {r: v["support"] for r, v in vs_world.items()}
    report["f1_true_pixels_vs_world"] = {r: v["f1"] for r, v in prf(truth_table, world).items()}
    report["relations"] = {"vs_true_pixels": vs_pixel, "vs_world": vs_world}
    report["notes"] = _notes(report)
    report["meta"] = _meta(data, manifest, list(lab[f"gradcam_map_{data.cameras[-1]}"].shape[-2:]))
    if own:
        report["meta"]["own_scene"] = {"adapter": own["name"], "objects": list(data.colours),
                                       "object_width": own["object_width"], "labeler_notes": own["notes"],
                                       "oracle": "f1_vs_world: against the scene's oracle, its objects' true "
                                                 "positions (object_positions) read along each role camera's own "
                                                 "axes (zsrm.envs.scene_task.role_axes) with thresholds scaled to "
                                                 "object_width, as SceneTask's oracle reads them"}
    report["stacked_pairs"] = _stacked_pairs(pixels["front"], truth_pixels["front"], truth_table,
                                             labelers(data, cfg)[scene0].thresholds["front"])
    if data.table_homography.get(scene0):
        report["close_pairs"] = _close_pairs(data, cfg, lab["gradcam_xy_tilted"], arr["pixels_tilted"], arr["present"],
                                             scene_index)
    report["meta"]["shortfalls"] = _shortfalls(report, labelers(data, cfg)[scene0].thresholds,
                                               data.block_width_px[scene0], set(data.table_homography.get(scene0, {})))
    return report


def _localisation(data: ExplorationData, lab: dict, arr: dict) -> dict:
    """Per camera: Grad-CAM's localisation error (also of the paper's plain argmax), wrong-object
    and not-located rates, and the AUROC of its presence score."""
    present, size, scene0 = arr["present"], data.config["image_size"], data.scenes[0]
    widths = np.array([[data.block_width_px[s][c] for c in data.cameras] for s in data.scenes])[arr["scene"]]
    report: dict = {k: {} for k in ("median_px_error", "p90_px_error", "block_width_px", "median_block_widths",
                                    "median_px_error_argmax", "p90_px_error_argmax", "wrong_object_rate",
                                    "not_located_rate", "median_px_error_by_colour", "presence_auroc")}
    for j, cam in enumerate(data.cameras):
        truth = arr[f"pixels_{cam}"].astype(np.float64)
        xy = lab[f"gradcam_xy_{cam}"]
        err = _errors(xy, truth, present)
        s = _summary(err)
        report["median_px_error"][cam], report["p90_px_error"][cam] = s["median"], s["p90"]
        report["block_width_px"][cam] = data.block_width_px[scene0][cam]
        report["median_block_widths"][cam] = _summary(err / widths[:, j:j + 1])["median"]
        report["wrong_object_rate"][cam] = _wrong_object(xy, truth, present)
        report["not_located_rate"][cam] = float(np.isinf(err[present]).mean())
        report["median_px_error_by_colour"][cam] = {
            c: _summary(err[:, i])["median"] for i, c in enumerate(data.colours) if present[:, i].any()}
        # The paper's state extractor: the argmax cell's geometric centre, from the stored maps.
        maps = lab[f"gradcam_map_{cam}"].astype(np.float32)
        plain = locate(maps, grid_centres(maps.shape[-2:], (size, size)), "argmax")
        s = _summary(_errors(plain, truth, present))
        report["median_px_error_argmax"][cam], report["p90_px_error_argmax"][cam] = s["median"], s["p90"]
        score = lab[f"gradcam_score_{cam}"]
        allowed = np.isfinite(score)
        report["presence_auroc"][cam] = auroc(score[allowed], present[allowed])
    return report


def _box_localisation(data: ExplorationData, lab: dict, arr: dict) -> dict:
    """Per camera, on the images whose scene holds the box: the median and 90th percentile
    distance (pixels) from the Grad-CAM of "a box" to the box's true centre, and the number of images."""
    present = arr["box_present"][:, None]
    report: dict = {"median_px_error_box": {}, "p90_px_error_box": {}, "box_images": int(present.sum())}
    for cam in data.cameras:
        err = _errors(lab[f"gradcam_box_xy_{cam}"][:, None], arr[f"box_pixels_{cam}"][:, None].astype(np.float64),
                      present)
        s = _summary(err)
        report["median_px_error_box"][cam], report["p90_px_error_box"][cam] = s["median"], s["p90"]
    return report


def _meta(data: ExplorationData, manifest: dict, grid: list) -> dict:
    return {
        "images": len(data),
        "scenes": list(data.scenes),
        "cameras": list(data.cameras),
        "image_size": data.config["image_size"],
        "gradcam_grid": grid,
        "collect": data.config,
        "label": manifest["config"],
        "f1_reference": "captions from the TRUE pixel coordinates (projected object centres) through the "
                        "same Table 1 rules and pixel thresholds; f1_vs_world: against the world oracle "
                        "(holds_in_world on true 3-D positions), which adds the error of reading relations "
                        "off one 2-D view (e.g. a farther block looks higher on the front camera)",
        "px_error": "distance from the Grad-CAM coordinates to the projection of the object's true centre, "
                    "present objects only; *_argmax: the paper's plain argmax cell centre of the same maps",
    }


def _close_pairs(data, cfg, xy, truth, present, scene_index) -> dict:
    """On the tilted camera read on the table, for the pairs that truly are "close to": the
    median centre distance in metres from the true and from the Grad-CAM points."""
    dist = {"true": [], "gradcam": []}
    close_m = world_thresholds(data, cfg).close
    for s, scene in enumerate(data.scenes):
        rows = np.nonzero(scene_index == s)[0]
        h = data.table_homography.get(scene, {}).get("tilted")
        if h is None or not len(rows):
            continue
        pts = {"true": apply_homography(h, truth[rows].astype(np.float64)),
               "gradcam": apply_homography(h, xy[rows].astype(np.float64))}
        for a in range(present.shape[1]):
            for b in range(a + 1, present.shape[1]):
                both = present[rows, a] & present[rows, b]
                d = {k: np.linalg.norm(v[:, a] - v[:, b], axis=-1) for k, v in pts.items()}
                close = both & (d["true"] < close_m)
                for k in dist:
                    dist[k].append(d[k][close])
    d = {k: np.concatenate(v) if v else np.zeros(0) for k, v in dist.items()}
    if not len(d["true"]):
        return {"n": 0}
    return {"n": int(len(d["true"])), "median_m_true": float(np.median(d["true"])),
            "median_m_gradcam": float(np.nanmedian(d["gradcam"])),
            "share_over_close_gradcam": float((~(d["gradcam"] < close_m)).mean())}


def _notes(report: dict) -> list[str]:
    notes = []
    for rel, f1 in report["f1"].items():
        need = 0.9 if rel in ("left_of", "right_of") else 0.8
        support = report["support"][rel]
        if f1 is None:
            notes.append(f"{rel}: F1 undefined: no true or predicted instance in this data (support {support})")
        elif f1 < need:
            notes.append(f"{rel}: F1 {f1:.2f} is below {need} (support {support})")
        elif support < MIN_SUPPORT:
            notes.append(f"{rel}: only {support} true instances: the F1 is noisy")
    return notes


# The threshold of Table 1 each relation's decision turns on (what a localisation error must beat).
_DECIDING = {"left_of": "gap", "right_of": "gap", "on_top_of": "eps_x", "below": "eps_x", "in_between": "gap",
             "in_front_of": "gap", "behind": "gap", "close_to": "close", "inside_of": "inside"}


def _stacked_pairs(xy: np.ndarray, truth: np.ndarray, table: RelationTable, thresholds=None) -> dict:
    """On the front camera, for the pairs that truly are "on top of": the median vertical and
    horizontal separation in pixels of the true centres and of the Grad-CAM points."""
    holds = table.holds["on_top_of"]
    n, t = np.nonzero(holds)
    if not len(n):
        return {"n": 0}
    a, b = table.tuples["on_top_of"][t].T
    out = {"n": int(len(n))}
    for name, pts in (("true", truth.astype(np.float64)), ("gradcam", xy.astype(np.float64))):
        d = pts[n, b] - pts[n, a]  # the lower block minus the upper one: +row is down
        out[f"median_dy_px_{name}"] = float(np.nanmedian(d[:, 1]))
        out[f"median_abs_dx_px_{name}"] = float(np.nanmedian(np.abs(d[:, 0])))
        if thresholds is not None:  # which of on_top_of's conditions the points break
            out[f"share_dx_over_eps_x_{name}"] = float((np.abs(d[:, 0]) >= thresholds.eps_x).mean())
            out[f"share_dy_outside_gap_eps_y_{name}"] = float(((d[:, 1] <= thresholds.gap)
                                                              | (d[:, 1] >= thresholds.eps_y)).mean())
    return out


def _shortfalls(report: dict, px: dict, widths: dict, table_cameras=frozenset()) -> list[str]:
    """Which targets this report misses, and the numbers that say why: each short relation's
    camera's median Grad-CAM error against the pixel threshold its decision turns on."""
    out = []
    front = report["median_px_error"].get("front")
    if front is not None and front > widths["front"] / 2:
        out.append(f"localisation: front median error {front:.2f} px > half a block width "
                   f"({widths['front'] / 2:.2f} px); the paper's plain argmax of the same maps gives "
                   f"{report['median_px_error_argmax']['front']:.2f} px; the Grad-CAM layer's cells are "
                   f"{report['meta']['image_size'] / report['meta']['gradcam_grid'][-1]:.0f} px wide and {report['wrong_object_rate']['front']:.0%} "
                   "of front locations land nearer another object than the named one")
    for rel, f1 in report["f1"].items():
        need = 0.9 if rel in ("left_of", "right_of") else 0.8
        if f1 is not None and f1 >= need:
            continue
        cam = RELATIONS[rel].camera
        name = _DECIDING[rel]
        thr = getattr(px[cam], name)
        f1_text = "undefined" if f1 is None else f"{f1:.2f}"
        if cam in table_cameras:  # read on the table in metres: compare distances, not pixels
            pairs = report.get("close_pairs", {})
            where = (f"it is read on the {cam} camera mapped onto the table, where its {name} threshold is "
                     f"{thr:.3f} m" + (f"; on true close pairs the Grad-CAM points are {pairs['median_m_gradcam']:.3f} m "
                                       f"apart (true {pairs['median_m_true']:.3f} m) and "
                                       f"{pairs['share_over_close_gradcam']:.0%} of them read over the threshold"
                                       if pairs.get("n") and rel == "close_to" else ""))
        else:
            where = (f"it is read on the {cam} camera, whose median Grad-CAM error "
                     f"{report['median_px_error'][cam]:.2f} px is {report['median_px_error'][cam] / thr:.1f}x "
                     f"its {name} threshold ({thr:.2f} px)")
        out.append(f"{rel}: F1 {f1_text} < {need} (P {_fmt(report['precision'][rel])}, R {_fmt(report['recall'][rel])}, "
                   f"support {report['support'][rel]}); {where}; even true pixel coordinates give F1 "
                   f"{_fmt(report['f1_true_pixels_vs_world'][rel])} against the world oracle (Table 1 read off "
                   "2-D views)" + (f"; only {report['support'][rel]} true instances" if report['support'][rel] < MIN_SUPPORT
                                   else "")
                   + (f"; on true stacked pairs the Grad-CAM points are {report['stacked_pairs']['median_dy_px_gradcam']:.2f} px "
                      f"apart vertically (true {report['stacked_pairs']['median_dy_px_true']:.2f} px) and "
                      f"{report['stacked_pairs']['median_abs_dx_px_gradcam']:.2f} px sideways (true "
                      f"{report['stacked_pairs']['median_abs_dx_px_true']:.2f} px); "
                      f"{report['stacked_pairs']['share_dx_over_eps_x_gradcam']:.0%} of them break |dx| < eps_x "
                      f"({px['front'].eps_x:.2f} px) and "
                      f"{report['stacked_pairs']['share_dy_outside_gap_eps_y_gradcam']:.0%} gap < dy < eps_y"
                      if rel in ("on_top_of", "below") and report["stacked_pairs"].get("n") else ""))
    return out


def write_tables(report: dict, csv_prefix: str | Path) -> list[Path]:
    """The report's per-camera and per-relation numbers as two CSV files."""
    prefix = Path(csv_prefix)
    cams = prefix.with_name(prefix.name + "_cameras.csv")
    rows = ["camera,median_px_error,p90_px_error,block_width_px,median_block_widths,median_px_error_argmax,"
            "wrong_object_rate,presence_auroc"]
    for cam in report["median_px_error"]:
        rows.append(",".join(_fmt(report[k][cam]) for k in (
            "median_px_error", "p90_px_error", "block_width_px", "median_block_widths", "median_px_error_argmax",
            "wrong_object_rate", "presence_auroc")).join([cam + ",", ""]))
    write_text(cams, "\n".join(rows) + "\n")
    rels = prefix.with_name(prefix.name + "_relations.csv")
    rows = ["relation,precision,recall,f1,support,f1_vs_world,support_world"]
    for rel in report["f1"]:
        rows.append(",".join([rel] + [_fmt(report[k][rel]) for k in (
            "precision", "recall", "f1", "support", "f1_vs_world", "support_world")]))
    write_text(rels, "\n".join(rows) + "\n")
    return [cams, rels]


def _fmt(v) -> str:
    return "" if v is None else (f"{v:.4g}" if isinstance(v, float) else str(v))


def figure3(data_folder, vlm, out: str | Path, labels: str | Path = LABELS, index: int | None = None,
            phrases=("red", "yellow")) -> Path:
    """Figure 3 (d, e) of the paper, per camera: the image, and the Grad-CAM heat maps of
    "red block" and "yellow block" (white is highest), with the located (+) and true (o) centres."""
    plt = pyplot()

    data = ExplorationData(data_folder)
    manifest = read_manifest(data.labels_folder(labels))
    cfg = LabelConfig(**manifest["config"])
    idx = [COLOURS.index(c) for c in phrases]
    index, one = _one_image(data, idx, index, phrases)
    shape = SCENE_SHAPES[data.scenes[int(one["scene"][0])]]
    grounder = Grounder(vlm, cfg, data, manifest.get("centres"), manifest.get("fine_centres"),
                        silhouettes=manifest.get("silhouettes"))
    grad = grounder.shard({k: v for k, v in one.items() if k.startswith("images_") or k == "scene"})
    size = data.config["image_size"]

    fig, axes = plt.subplots(len(data.cameras), 3, figsize=(7.5, 2.6 * len(data.cameras)), squeeze=False)
    marker_colour = {"red": "#ff3030", "yellow": "#ffd21a", "green": "#30c040", "blue": "#3060ff"}
    for r, cam in enumerate(data.cameras):
        image = one[f"images_{cam}"][0]
        axes[r, 0].imshow(image)
        axes[r, 0].set_ylabel(cam)
        axes[r, 0].set_title("image" if r == 0 else "")
        for c, (colour, k) in enumerate(zip(phrases, idx), start=1):
            heat = grad[f"gradcam_map_{cam}"][0, k].astype(np.float32)
            ax = axes[r, c]
            # Cells drawn over the pixels they cover, bilinear like the usual Grad-CAM overlay.
            ax.imshow(heat, cmap="gray", interpolation="bilinear", extent=(-0.5, size - 0.5, size - 0.5, -0.5),
                      vmin=0, vmax=max(float(heat.max()), 1e-12))
            gx, gy = grad[f"gradcam_xy_{cam}"][0, k]
            tx, ty = one[f"pixels_{cam}"][0, k]
            ax.plot([gx], [gy], "+", color=marker_colour[colour], ms=12, mew=2)
            ax.plot([tx], [ty], "o", mfc="none", mec=marker_colour[colour], ms=9, mew=1.5)
            if r == 0:
                ax.set_title(f"Grad-CAM '{colour} {shape}'")
        for ax in axes[r]:
            ax.set_xticks([])
            ax.set_yticks([])
    refined = "; tilted: silhouette-refined" if grounder.silhouettes else ""
    fig.suptitle(f"Grad-CAM grounding ({cfg.vlm}), image {index}: + located ({cfg.locate}{refined}), o true centre",
                 fontsize=9)
    return save_figure(fig, out)


def _one_image(data: ExplorationData, idx: list[int], index: int | None, phrases) -> tuple[int, dict]:
    """(index, arrays of that one image): the given one, or the first that holds all ``idx`` colours.
    Only the image's own shard is loaded."""
    if index is None:
        candidates = np.nonzero(data.load(["present"])["present"][:, idx].all(1))[0]
        if not len(candidates):
            raise ValueError(f"no image holds both {' and '.join(phrases)} objects")
        index = int(candidates[0])
    start = 0
    for name in data.shards:
        n = data.manifest["shards"][name]["images"]
        if index < start + n:
            break
        start += n
    return index, {k: v[index - start:index - start + 1] for k, v in data.shard(name).items()}


def save_report(report: dict, out: str | Path) -> Path:
    """The report as JSON with flat dotted keys (see :func:`flatten`)."""
    return write_json(out, flatten(report))


def flatten(report: dict, keep: tuple[str, ...] = ("meta", "notes", "relations")) -> dict:
    """Nested report -> flat dotted keys (``median_px_error.front``); ``keep`` stay nested.

    >>> flatten({"f1": {"left_of": 0.9}, "meta": {"images": 4}})
    {'f1.left_of': 0.9, 'meta': {'images': 4}}
    """
    out: dict = {}

    def walk(prefix: str, value):
        if isinstance(value, dict) and prefix not in keep:
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        else:
            out[prefix] = value

    walk("", report)
    return out
