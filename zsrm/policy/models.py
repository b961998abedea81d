"""The three distilled policies of the paper's section 3.3, one class.

* ``language``: the image encoding and the goal's text embedding, each through an fc layer,
  concatenated, then two fc layers to the action;
* ``primitive``: the same with a one-hot primitive code (the index of a training task) in
  place of the text; a goal is mapped to the training task whose text embedding is nearest in
  L2 distance (:meth:`DistilledPolicy.condition`), so test goals get a training task's code;
* ``none``: two fc layers on the image encoding alone;
* ``grounded`` (zsrm's variant, not the paper's): the language policy whose goal objects are
  found by the scene VLM's Grad-CAM, as the reward's labeler finds them. The goal's two noun
  phrases pick, through the VLM's image-text space, where each object is (a Grad-CAM map of
  the frozen trunk's features, read as a centroid and a score) and the relation's words go
  through the fc layer. A colour the policy never saw is found the way the VLM finds it.

Image towers: ``resnet18`` (torchvision's, the paper's; ImageNet weights when the user has
them) or ``scene`` (the scene VLM's image trunk, its Grad-CAM layer, read by spatial-softmax
keypoints as the RL policies read it). ``keypoint_view`` sets which frames the tower reads: in
colour (the paper's), in grey (the ``cpu`` schedule's default, :mod:`zsrm.policy.training`), or as
shapes. Saved as one folder: ``config.json`` (kind
``zsrm-multitask-policy``, :class:`PolicyConfig`) and ``model.safetensors``, never pickle.
The training tasks' text embeddings are kept in the weights (``goal_embeddings``).

>>> cfg = PolicyConfig(conditioning="primitive", tower="scene", image_size=64, action_dim=3, text_dim=8,
...                    goals=("a red block on top of a green block", "a green block on top of a red block"),
...                    scene=SceneConfig(widths=(8, 8, 8), groups=4), hidden=16, keypoints=4)
>>> policy = DistilledPolicy(cfg)
>>> images = torch.zeros(5, 3, 64, 64, dtype=torch.uint8)
>>> tuple(policy(images, torch.zeros(5, dtype=torch.long)).shape)
(5, 3)
"""
from __future__ import annotations

import contextlib
import io
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import torch
import torch.nn.functional as F
from torch import nn

from zsrm.common.registry import WEIGHTS_FILE, build_model, load_weights, read_config, save_folder
from zsrm.grounding.gradcam import GradCAM, head_gradcam
from zsrm.rl.features import SpatialSoftmax
from zsrm.tasks.language import parse_goal
from zsrm.tasks.relations import RELATIONS
from zsrm.vlm.scene import SceneConfig, SceneImageTower, mean_max_pool

KIND = "zsrm-multitask-policy"
CONDITIONINGS = ("language", "primitive", "none", "grounded")
GROUNDED_OBJECTS = 2  # the goal's objects a grounded policy locates (a two-object relation)
KEYPOINT_VIEWS = ("colour", "grey", "shape", "none")
IMAGE_VIEWS = KEYPOINT_VIEWS[:3]  # what the paper's three policies can read (they need image features)
LUMA = (0.299, 0.587, 0.114)  # ITU-R BT.601: grey frames for keypoint_view="grey"
# keypoint_view="shape": a pixel this saturated is a coloured object's and is painted SHAPE_GREY.
# In the rendered scenes the table and the sky are at most 0.4 and every block colour, blue
# included, at least 0.7 (64 px frames).
SHAPE_SATURATION, SHAPE_GREY = 0.55, 128.0
IMAGENET_MEAN, IMAGENET_STD = (0.485, 0.456, 0.406), (0.229, 0.224, 0.225)


@dataclass
class PolicyConfig:
    """A distilled policy's architecture and what it reads (saved in config.json)."""

    conditioning: Literal["language", "primitive", "none", "grounded"]
    tower: Literal["scene", "resnet18"]
    image_size: int  # frames are (image_size, image_size) from `camera`
    action_dim: int
    text_dim: int  # size of the goal's text embedding
    goals: tuple[str, ...]  # the training tasks' goal sentences: primitive code i is goals[i]
    scene: SceneConfig | None = None  # the scene tower's architecture (tower scene)
    hidden: int = 256  # width of the fc layers
    keypoints: int = 32  # spatial-softmax keypoints on the scene tower's map
    vlm: str = "scene"  # the VLM whose text tower embeds goals
    text_embedding: Literal["language", "joint", "grounded"] = "language"  # see zsrm.policy.models.embed_goals
    # What the policy's own image features look at: the frames, the frames in grey, the frames in
    # grey with every coloured object one grey (shapes, no colour to tell the blocks apart by; a
    # grounded policy's keypoints get their own trunk copy, which trains), or, for a grounded
    # policy only, nothing (the goal objects' grounding is all it sees).
    keypoint_view: Literal["colour", "grey", "shape", "none"] = "colour"
    camera: str = "front"
    action_repeat: int = 2  # control steps per decision, as the task policies acted
    centre_text: bool = False  # language policy: goal embeddings centred and scaled (DistilledPolicy.centred)
    # Language policy: each goal's embedding projected onto the training goals' span
    # (DistilledPolicy.in_goal_span); a training goal's is unchanged, so set at evaluation.
    text_span: bool = False

    def __post_init__(self):
        if self.conditioning not in CONDITIONINGS:
            raise ValueError(f"unknown conditioning {self.conditioning!r}; choose one of {', '.join(CONDITIONINGS)}")
        if self.tower == "scene" and self.scene is None:
            self.scene = SceneConfig()
        if (self.conditioning == "grounded") != (self.text_embedding == "grounded"):
            raise ValueError("the grounded policy, and only it, reads grounded goal embeddings")
        if self.conditioning == "grounded" and self.tower != "scene":
            raise ValueError("the grounded policy finds objects with the scene VLM's Grad-CAM: use --tower scene")
        if self.keypoint_view not in KEYPOINT_VIEWS:
            raise ValueError(f"unknown keypoint view {self.keypoint_view!r}; choose one of {', '.join(KEYPOINT_VIEWS)}")
        if (self.centre_text or self.text_span) and self.conditioning != "language":
            raise ValueError("only the language policy reads centred or span-projected goal embeddings")
        if self.keypoint_view == "none" and self.conditioning != "grounded":
            raise ValueError("only the grounded policy can do without image features of its own (keypoint view none)")
        if min(self.image_size, self.action_dim, self.text_dim, len(self.goals), self.hidden, self.keypoints) < 1:
            raise ValueError("image_size, action_dim, text_dim, hidden, keypoints and the goals must be positive")


def resnet18(pretrained: bool) -> nn.Module:
    """torchvision's ResNet18 without its classifier (512 features); ``pretrained``: its
    ImageNet weights, which torchvision downloads on first use (one clear line offline)."""
    from zsrm.vlm.compat import import_torchvision

    tv = import_torchvision()
    try:  # torch.hub announces each download on stdout: the failure below is the one line
        with contextlib.redirect_stdout(io.StringIO()):
            net = tv.models.resnet18(weights="IMAGENET1K_V1" if pretrained else None)
    except (OSError, RuntimeError) as err:  # URLError is an OSError
        raise ValueError(f"cannot get ResNet18's ImageNet weights ({str(err).splitlines()[0][:120]}): put "
                         "resnet18-f37072fd.pth in torch's hub cache, pass --no-pretrained, or use --tower scene") \
            from None
    net.fc = nn.Identity()
    return net


class ImageEncoder(nn.Module):
    """uint8 frames (N, 3, H, W) -> a feature vector per frame (``out_dim``)."""

    def __init__(self, cfg: PolicyConfig, pretrained: bool = False, keypoints: bool = True):
        """``keypoints=False``: the scene trunk alone (``out_dim`` 0), for a grounded policy whose
        keypoints look at nothing."""
        super().__init__()
        if cfg.tower == "resnet18":
            mean, std = IMAGENET_MEAN, IMAGENET_STD
            self.net, self.out_dim = resnet18(pretrained), 512
        else:
            mean, std = cfg.scene.mean, cfg.scene.std
            t = SceneImageTower(cfg.scene)
            trunk = nn.Sequential(t.stem, t.layer1, t.down, t.layer2, t.final)
            with torch.no_grad():
                _, c, h, w = trunk(torch.zeros(1, 3, cfg.image_size, cfg.image_size)).shape
            if keypoints:
                heat = nn.Sequential(nn.Conv2d(c, 64, 1), nn.ReLU(), nn.Conv2d(64, cfg.keypoints, 1))
                self.net, self.out_dim = nn.Sequential(trunk, heat, SpatialSoftmax(h, w)), 3 * cfg.keypoints
            else:
                self.net, self.out_dim = nn.Sequential(trunk), 0
        self.register_buffer("mean", torch.tensor(mean).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(std).view(1, 3, 1, 1))

    def normalise(self, images: torch.Tensor) -> torch.Tensor:
        return (images.float() / 255.0 - self.mean) / self.std

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        return self.net(self.normalise(images))

    def load_scene_trunk(self, vlm) -> None:
        """Start the scene tower from a scene VLM's image trunk (its pretrained weights)."""
        v = vlm.visual
        self.net[0].load_state_dict(nn.Sequential(v.stem, v.layer1, v.down, v.layer2, v.final).state_dict())


class DistilledPolicy(nn.Module):
    """Frames and a condition (text embeddings, primitive codes, or None) to actions."""

    def __init__(self, cfg: PolicyConfig, pretrained: bool = False):
        super().__init__()
        self.cfg = cfg
        grounded = cfg.conditioning == "grounded"
        self.encoder = ImageEncoder(cfg, pretrained, keypoints=not (grounded and cfg.keypoint_view in ("none", "shape")))
        f, h, a = self.encoder.out_dim, cfg.hidden, cfg.action_dim
        if grounded and cfg.keypoint_view == "shape":
            # Shape frames show no colour, so this trunk can learn the gripper without learning
            # to tell three colours apart.
            self.shape_encoder = ImageEncoder(cfg, pretrained)
            f = self.shape_encoder.out_dim
        width = {"language": cfg.text_dim, "primitive": len(cfg.goals)}.get(cfg.conditioning)
        if cfg.conditioning == "grounded":
            # The trunk stays the VLM's (fine-tuning it on three colours would lose the fourth),
            # and so does the head its Grad-CAM goes through.
            self.encoder.net[0].requires_grad_(False)
            self.grounding_proj = nn.Linear(2 * cfg.scene.widths[2], cfg.scene.embed_dim).requires_grad_(False)
            f += 3 * GROUNDED_OBJECTS  # and each object's centroid and score
            width = cfg.text_dim - GROUNDED_OBJECTS * cfg.scene.embed_dim  # the relation's words
        if cfg.conditioning == "none":
            self.head = nn.Sequential(nn.Linear(f, h), nn.ReLU(), nn.Linear(h, a))
        else:
            self.image_fc = nn.Sequential(nn.Linear(f, h), nn.ReLU())
            self.condition_fc = nn.Sequential(nn.Linear(width, h), nn.ReLU())
            self.head = nn.Sequential(nn.Linear(2 * h, h), nn.ReLU(), nn.Linear(h, a))
        self.register_buffer("goal_embeddings", torch.zeros(len(cfg.goals), cfg.text_dim))

    def forward(self, images: torch.Tensor, condition: torch.Tensor | None = None) -> torch.Tensor:
        if self.cfg.conditioning == "grounded":
            return self._grounded(images, condition)
        z = self.encoder(view_frames(images, self.cfg.keypoint_view))
        if self.cfg.conditioning == "none":
            return self.head(z)
        if self.cfg.conditioning == "primitive":
            condition = F.one_hot(condition.long(), len(self.cfg.goals)).float()
        elif self.cfg.centre_text:
            condition = self.centred(condition)
        return self.head(torch.cat([self.image_fc(z), self.condition_fc(condition)], dim=1))

    def _grounded(self, images: torch.Tensor, condition: torch.Tensor) -> torch.Tensor:
        trunk, keypoints = self.encoder.net[0], self.encoder.net[1:]
        with torch.no_grad():
            feats = trunk(self.encoder.normalise(images))
        n, e = feats.shape[0], self.cfg.scene.embed_dim
        split = GROUNDED_OBJECTS * e
        maps, scores = head_gradcam(lambda f: self.grounding_proj(mean_max_pool(f)), feats,
                                    condition[:, :split].reshape(n, GROUNDED_OBJECTS, e))
        z = [map_centroids(maps).flatten(1), scores]
        if self.cfg.keypoint_view == "grey":
            with torch.no_grad():
                feats = trunk(self.encoder.normalise(grey_frames(images)))
        if self.cfg.keypoint_view in ("colour", "grey"):
            z.insert(0, keypoints(feats))
        elif self.cfg.keypoint_view == "shape":
            z.insert(0, self.shape_encoder(shape_frames(images)))
        z = torch.cat(z, dim=1)
        return self.head(torch.cat([self.image_fc(z), self.condition_fc(condition[:, split:])], dim=1))

    def load_scene_vlm(self, vlm) -> None:
        """Start the scene tower (and a grounded policy's Grad-CAM head) from a scene VLM."""
        self.encoder.load_scene_trunk(vlm)
        if hasattr(self, "shape_encoder"):
            self.shape_encoder.load_scene_trunk(vlm)
        if self.cfg.conditioning == "grounded":
            self.grounding_proj.load_state_dict(vlm.visual.proj.state_dict())

    def centred(self, embeddings: torch.Tensor) -> torch.Tensor:
        """Goal embeddings less the training goals' mean, over the training goals' RMS distance
        from it. The 18 goals' sentence embeddings share cosines of 0.83-0.99, so raw they differ
        by a few hundredths per dimension; centred, by about as much as one-hot codes do. One
        scale for all dimensions keeps the embedding's geometry, a test goal's included."""
        mean = self.goal_embeddings.mean(dim=0)
        scale = (self.goal_embeddings - mean).pow(2).sum(dim=1).mean().sqrt().clamp_min(1e-8)
        return (embeddings - mean) / scale

    def in_goal_span(self, embeddings: torch.Tensor) -> torch.Tensor:
        """Goal embeddings projected onto the affine span of the training goals' embeddings.
        The text fc layer is trained on those alone, so nothing the loss sees constrains what its
        weights do along any other direction; a test goal's component there (for the blue goals,
        44-74% of its squared distance from the training goals' mean) passes through weights that
        no data fitted. A training goal's embedding is its own projection: the policy is the
        same on them."""
        mean = self.goal_embeddings.mean(dim=0)
        _, singular, basis = torch.linalg.svd(self.goal_embeddings - mean, full_matrices=False)
        basis = basis[singular > singular[0] * 1e-5]
        return mean + (embeddings - mean) @ basis.T @ basis

    def nearest_codes(self, embeddings: torch.Tensor) -> torch.Tensor:
        """The primitive code of each goal embedding: the training task nearest in L2 distance."""
        return torch.cdist(embeddings.float(), self.goal_embeddings).argmin(dim=1)

    def condition(self, embeddings: torch.Tensor) -> torch.Tensor | None:
        """What :meth:`forward` reads for goals given by their text embeddings (N, text_dim)."""
        if self.cfg.conditioning in ("language", "grounded"):
            return self.in_goal_span(embeddings.float()) if self.cfg.text_span else embeddings.float()
        return self.nearest_codes(embeddings) if self.cfg.conditioning == "primitive" else None

    @torch.no_grad()
    def act(self, frames, embeddings: torch.Tensor) -> "torch.Tensor":
        """Actions in [-1, 1] for camera frames (N, H, W, 3) uint8 and their goals' embeddings."""
        images = torch.as_tensor(frames).permute(0, 3, 1, 2)
        return self(images, self.condition(embeddings)).clamp(-1.0, 1.0)


def view_frames(images: torch.Tensor, view: str) -> torch.Tensor:
    """(N, 3, H, W) frames as ``view`` shows them: as they are (colour), grey, or shapes."""
    return {"grey": grey_frames, "shape": shape_frames}.get(view, lambda x: x)(images)


def grey_frames(images: torch.Tensor) -> torch.Tensor:
    """(N, 3, H, W) frames (0-255) in grey, the luma in all three channels (float)."""
    return (images.float() * torch.tensor(LUMA).view(1, 3, 1, 1)).sum(1, keepdim=True).expand_as(images)


def shape_frames(images: torch.Tensor) -> torch.Tensor:
    """(N, 3, H, W) frames (0-255) in grey with every coloured object's pixel SHAPE_GREY: the
    objects' shapes and the gripper, and nothing to tell one colour from another (float)."""
    x = images.float()
    high, low = x.amax(dim=1, keepdim=True), x.amin(dim=1, keepdim=True)
    coloured = (high - low) > SHAPE_SATURATION * high.clamp_min(1e-6)
    return torch.where(coloured.expand_as(x), torch.full_like(x, SHAPE_GREY), grey_frames(images))


def map_centroids(maps: torch.Tensor, fraction: float = 0.5) -> torch.Tensor:
    """(N, P, h, w) heat maps -> (N, P, 2) centroids (x, y) in [-1, 1] of the cells above
    ``fraction`` of each map's peak (0, 0 for an empty map)."""
    h, w = maps.shape[-2:]
    mass = torch.relu(maps / maps.amax(dim=(-2, -1), keepdim=True).clamp_min(1e-8) - fraction)
    total = mass.sum(dim=(-2, -1)).clamp_min(1e-8)
    x = (mass * torch.linspace(-1, 1, w)).sum(dim=(-2, -1)) / total
    y = (mass * torch.linspace(-1, 1, h)[:, None]).sum(dim=(-2, -1)) / total
    return torch.stack([x, y], dim=-1)


def embed_goals(vlm, goals, kind: str = "language") -> torch.Tensor:
    """Goal sentences' text embeddings (M, D). ``language``: the VLM's language encoder as it
    is (the paper feeds CLIP's language encoding; for the scene VLM, its frozen sentence encoder,
    before the projection that pretraining on presence-only captions taught to ignore
    relation words); ``joint``: the normalised embedding in the image-text space; ``grounded``:
    each object phrase's Grad-CAM target vector (contrasted with the goal's other phrase: no
    other colour's words enter) then the relation words' language encoding."""
    goals = list(goals)

    def language(texts):
        if hasattr(vlm, "sentence_features"):
            return vlm.sentence_features(texts).float().cpu()
        return vlm.encode_texts(texts, normalize=True).float().cpu()

    with torch.no_grad():
        if kind == "language":
            return language(goals)
        if kind == "joint":
            return vlm.encode_texts(goals, normalize=True).float().cpu()
        if kind != "grounded":
            raise ValueError(f"unknown goal embedding {kind!r}; choose language, joint or grounded")
        tasks, cam = [parse_goal(g) for g in goals], GradCAM(vlm)
        for goal, task in zip(goals, tasks):
            if len(task.objects) != GROUNDED_OBJECTS:
                raise ValueError(f"the grounded policy reads goals about {GROUNDED_OBJECTS} objects; {goal!r} "
                                 f"names {len(task.objects)}")
        targets = torch.stack([cam.target_vectors(t.phrases).flatten().cpu() for t in tasks])
        return torch.cat([targets, language([RELATIONS[t.relation].phrase for t in tasks])], dim=1)


def save_policy(policy: DistilledPolicy, folder: str | Path, training: dict | None = None) -> None:
    save_folder(folder, {"kind": KIND, "config": asdict(policy.cfg), "training": training or {}},
                {WEIGHTS_FILE: policy})


def load_policy(folder: str | Path) -> DistilledPolicy:
    """A saved distilled policy: its config checked against :class:`PolicyConfig` and its
    weights' names, shapes and dtypes against the policy that describes, before loading."""
    config = read_config(folder, kind=KIND, schema={"kind": str, "config": PolicyConfig, "training": dict})
    policy = build_model(folder, lambda: DistilledPolicy(config.config))
    load_weights(policy, folder)
    return policy.eval()
