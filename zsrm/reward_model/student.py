"""A small reward network trained from scratch on the generated pairs, for the RL inner loop.

The paper reports that training on the generated data from scratch works well. The student
is a four-layer CNN at 64 px whose last feature map is flattened (not pooled), so where an
object is stays in the embedding; its text side is a frozen VLM's text embeddings of the
sentence and of its object phrases in order (:class:`~zsrm.reward_model.text.RoleTextFeatures`,
computed once per text and cached) through a small trainable MLP. It implements the
:class:`~zsrm.vlm.base.VisionLanguageModel` interface, so it trains with the same loop as
the VLM and plugs into the same rewards.

>>> import numpy as np
>>> from zsrm.grounding.testing import ColourVLM
>>> net = StudentRewardNet(StudentConfig(image_size=32, widths=(8, 8, 8, 8), embed_dim=8), ColourVLM(), "testing")
>>> net.encode_images(np.zeros((2, 32, 32, 3), np.uint8)).shape
torch.Size([2, 8])
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np  # noqa: F401  (doctest)
import torch
from torch import nn

from zsrm.reward_model.text import RoleTextFeatures
from zsrm.vlm.base import ImageBatch, VisionLanguageModel, pixels_from_images

BACKEND = "zsrm-student"
# The student trained by `make results` (results/reward_eval.json), shipped so that the ZSRM
# reward works offline without training first: load it with the spec "student".
SHIPPED_STUDENT_DIR = Path(__file__).resolve().parent / "weights" / "student"
WEIGHTS_FILE = "model.safetensors"
CONFIG_FILE = "config.json"


@dataclass
class StudentConfig:
    image_size: int = 64
    widths: tuple[int, int, int, int] = (32, 64, 64, 128)  # four stride-2 convs: 64 px -> 4x4 map
    embed_dim: int = 128
    text_hidden: int = 256
    mean: tuple[float, float, float] = (0.5, 0.5, 0.5)
    std: tuple[float, float, float] = (0.25, 0.25, 0.25)

    def __post_init__(self):
        self.widths = tuple(int(w) for w in self.widths)
        self.mean, self.std = tuple(self.mean), tuple(self.std)
        if len(self.widths) != 4:
            raise ValueError(f"widths must have 4 entries, got {self.widths}")
        if self.image_size % 16:
            raise ValueError(f"image_size must be a multiple of 16, got {self.image_size}")


class StudentRewardNet(VisionLanguageModel):
    """CNN image tower + (frozen VLM text embedding -> MLP) text tower.

    ``text_vlm`` is any VisionLanguageModel; only its text tower is used, frozen, and it is
    not part of this model's weights (``text_vlm_spec`` says how to load it again).
    """

    backend = BACKEND
    gradcam_layer = "features"

    def __init__(self, config: StudentConfig, text_vlm: VisionLanguageModel, text_vlm_spec: str,
                 meta: dict | None = None):
        super().__init__()
        self.config = config
        self.image_size = config.image_size
        w = config.widths
        layers, cin = [], 3
        for cout in w:
            layers += [nn.Conv2d(cin, cout, 3, stride=2, padding=1), nn.ReLU()]
            cin = cout
        self.features = nn.Sequential(*layers)
        side = config.image_size // 16
        self.image_proj = nn.Sequential(nn.Flatten(), nn.Linear(w[-1] * side * side, config.embed_dim))
        # The text vlm is frozen and saved elsewhere: keep it out of this module's parameters.
        self.__dict__["text_vlm"] = text_vlm.eval().requires_grad_(False)
        self.text_vlm_spec = str(text_vlm_spec)
        with torch.no_grad():
            text_dim = text_vlm.encode_texts(["a red block on the left of a blue block"]).shape[-1]
        self.text_features = RoleTextFeatures(text_dim)
        self.text_proj = nn.Sequential(nn.Linear(self.text_features.out_dim, config.text_hidden), nn.ReLU(),
                                       nn.Linear(config.text_hidden, config.embed_dim))
        self.logit_scale = nn.Parameter(torch.tensor(math.log(1 / 0.07)))
        self.meta: dict = dict(meta or {})
        self._frozen_text: dict[str, torch.Tensor] = {}

    @property
    def device(self) -> torch.device:
        return self.logit_scale.device

    def preprocess(self, images: ImageBatch) -> torch.Tensor:
        return pixels_from_images(images, self.image_size, self.config.mean, self.config.std, device=self.device)

    def image_trunk(self, pixels: torch.Tensor) -> torch.Tensor:
        return self.features(pixels)

    def image_head(self, features: torch.Tensor) -> torch.Tensor:
        return self.image_proj(features)

    def frozen_text_features(self, texts: list[str]) -> torch.Tensor:
        """The text VLM's normalised embeddings, computed once per text."""
        missing = list(dict.fromkeys(t for t in texts if t not in self._frozen_text))
        if missing:
            with torch.no_grad():
                emb = self.text_vlm.encode_texts(missing).float().cpu()
            self._frozen_text.update(zip(missing, emb))
        return torch.stack([self._frozen_text[t] for t in texts]).to(self.device)

    def encode_text_tokens(self, texts: list[str]) -> torch.Tensor:
        return self.text_proj(self.text_features(self.frozen_text_features, list(texts)))

    def fit_text_statistics(self, texts: list[str]) -> None:
        """Whiten the frozen text embeddings with the statistics of these (training) texts."""
        self.text_features.fit(self.frozen_text_features, list(texts))

    # --- persistence ---------------------------------------------------------------------
    def save(self, folder: str | Path) -> None:
        from safetensors.torch import save_model

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        save_model(self, str(folder / WEIGHTS_FILE))
        spec = self.text_vlm_spec
        if Path(spec).is_dir():  # a folder moves with the student when both move together
            spec = os.path.relpath(Path(spec).resolve(), folder.resolve())
        config = {"backend": BACKEND, "config": asdict(self.config), "text_vlm": spec,
                  "text_vlm_is_folder": Path(self.text_vlm_spec).is_dir(), "meta": self.meta}
        (folder / CONFIG_FILE).write_text(json.dumps(config, indent=2) + "\n")

    @classmethod
    def from_folder(cls, folder: str | Path, device: str | torch.device = "cpu",
                    text_vlm: VisionLanguageModel | None = None) -> "StudentRewardNet":
        from safetensors.torch import load_model

        folder = Path(folder)
        cfg = read_student_config(folder)
        spec = cfg["text_vlm"]
        if cfg.get("text_vlm_is_folder"):
            spec = str((folder / spec).resolve())
        if text_vlm is None:
            try:
                text_vlm = load_reward_backbone(spec, device=device)
            except (FileNotFoundError, ValueError) as err:
                raise FileNotFoundError(f"the student in {folder} embeds texts with the VLM {spec!r}, "
                                        f"which does not load: {err}") from None
        model = cls(StudentConfig(**cfg["config"]), text_vlm, spec, meta=cfg.get("meta"))
        weights = folder / WEIGHTS_FILE
        if not weights.is_file():
            raise FileNotFoundError(f"no {WEIGHTS_FILE} in {folder}")
        load_model(model, str(weights), strict=True, device=str(device))
        return model.to(device).eval()


def read_student_config(folder: Path) -> dict:
    path = Path(folder) / CONFIG_FILE
    if not path.is_file():
        raise FileNotFoundError(f"no {CONFIG_FILE} in {folder}: not a saved zsrm model folder")
    cfg = json.loads(path.read_text())
    if cfg.get("backend") != BACKEND:
        raise ValueError(f"{folder} holds a {cfg.get('backend')!r} model, not a zsrm student")
    return cfg


def folder_backend(spec) -> str | None:
    """The ``backend`` a saved model folder's config.json names (None if ``spec`` is not one)."""
    path = Path(str(spec)).expanduser()
    if not (path / CONFIG_FILE).is_file():
        return None
    try:
        return json.loads((path / CONFIG_FILE).read_text()).get("backend")
    except json.JSONDecodeError:
        return None


def is_student_folder(spec) -> bool:
    return folder_backend(spec) == BACKEND


def load_reward_backbone(spec: str | Path, device: str | torch.device = "cpu") -> VisionLanguageModel:
    """A model folder written by ``zsrm finetune`` (fine-tuned VLM or student), ``"student"``
    (the shipped student), or any ``load_vlm`` spec (e.g. ``scene``, the base VLM)."""
    if str(spec) == "student":
        if not (SHIPPED_STUDENT_DIR / CONFIG_FILE).is_file():
            raise FileNotFoundError(f"the shipped student is missing from {SHIPPED_STUDENT_DIR}; reinstall zsrm "
                                    "or train one with zsrm finetune --student")
        spec = SHIPPED_STUDENT_DIR
    backend = folder_backend(spec)
    if backend == BACKEND:
        return StudentRewardNet.from_folder(spec, device)
    from zsrm.reward_model.adapted import BACKEND as ADAPTED, AdaptedVLM

    if backend == ADAPTED:
        return AdaptedVLM.from_folder(spec, device)
    from zsrm.vlm import load_vlm

    return load_vlm(str(spec), device=device)
