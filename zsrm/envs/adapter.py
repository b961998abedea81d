"""Your own scene for zsrm: the adapter a user writes so that zsrm's stages can read a scene it
was not built for (see docs/own-scene.md).

An adapter says, for one gymnasium env:

* which env: :attr:`SceneAdapter.env_id` (a registered gymnasium id, made with
  :meth:`SceneAdapter.make_env`), or :attr:`SceneAdapter.xml` alone, a MuJoCo XML that zsrm
  turns into an env (:class:`zsrm.envs.xml_scene.XmlSceneEnv`: its cameras' pixels in, actuator
  controls out); an XML given with an ``env_id`` has its cameras checked before any env is built;
* what is in it: :attr:`SceneAdapter.objects`, one noun phrase per object ("red mug",
  "blue plate"), the words goals and captions will use;
* which of its cameras play Table 1's roles: :attr:`SceneAdapter.cameras`, ``{"front": ...,
  "left": ..., "tilted": ...}`` (the left camera's image x axis points toward the front
  camera; the tilted one looks 45 degrees down onto the table);
* where exploration actions come from: :meth:`SceneAdapter.exploration_action` (uniform
  random by default);
* its geometry, for the labeler: :attr:`SceneAdapter.object_width` (a typical object's width)
  and, optionally, :attr:`SceneAdapter.table_height` (the surface the objects rest on: the
  tilted camera is then read on the table in metres);
* one privileged accessor, :meth:`SceneAdapter.object_positions`: the objects' true world
  positions (by default those of the bodies :attr:`SceneAdapter.bodies` names). ONLY the oracle, evaluation, and the scene stand-in VLM's presence-caption
  pretraining may call it. No reward model and no policy ever reads it: they get the
  cameras' images.

Adapters are named by ``module:Class`` (the current folder is importable, as with ``python
-m``), by an id given to :func:`register_scene`, or by an entry point of the group
``zsrm.scenes``. Everything wrong with one is a :class:`SceneAdapterError`, one line
(a ValueError: the command line prints it and exits with status 2).

>>> class Mugs(SceneAdapter):
...     env_id = "MyLab/Mugs-v0"
...     objects = ("red mug", "blue plate")
...     cameras = {"front": "cam0", "left": "cam1", "tilted": "cam2"}
>>> Mugs().roles["tilted"]
'cam2'
>>> class Bad(Mugs):
...     cameras = {"front": "cam0", "left": "cam1"}
>>> check_adapter(Bad())
Traceback (most recent call last):
...
zsrm.envs.adapter.SceneAdapterError: zsrm.envs.adapter:Bad: no camera plays the 'tilted' role; give cameras = {'front': ..., 'left': ..., 'tilted': ...}
"""
from __future__ import annotations

import importlib
import os
import re
import sys
from importlib.metadata import entry_points
from typing import Mapping

import gymnasium as gym
import mujoco
import numpy as np

from zsrm.tasks.relations import CAMERAS

ROLES = CAMERAS  # Table 1's cameras: front, left, tilted
ENTRY_POINT_GROUP = "zsrm.scenes"
# A noun phrase: lower-case words of letters, as goals are written ("red mug", "wooden spoon").
_PHRASE = re.compile(r"^[a-z]+(?: [a-z]+)*$")


class SceneAdapterError(ValueError):
    """An adapter zsrm cannot use, or one that cannot be loaded: one line saying what is wrong."""


class SceneAdapter:
    """Subclass it and fill in the class attributes; override a method only where your env
    differs from the defaults.

    The default :meth:`make_env` calls ``gym.make(env_id, cameras=..., image_size=...,
    objects=..., **env_kwargs)``: an env that takes the camera names to observe, a square image
    side and which objects to hold, and observes a dict ``{camera name: (size, size, 3) uint8
    image}``; without an ``env_id``, it builds an :class:`~zsrm.envs.xml_scene.XmlSceneEnv` of
    ``xml`` (``env_kwargs``: its ``frame_skip`` and ``jitter``), which always holds every object.
    Override :meth:`make_env` (and :meth:`observe`) for an env that is built or observes otherwise.
    """

    env_id: str | None = None  # a registered gymnasium id
    xml: str | None = None  # the scene's MuJoCo XML: the env itself when there is no env_id, else its cameras are checked early
    env_kwargs: Mapping = {}  # further keywords of gym.make (or of XmlSceneEnv)
    task_env_kwargs: Mapping = {}  # keywords added for the scenes a policy trains and is evaluated in (e.g. a start layout)
    objects: tuple[str, ...] = ()  # a noun phrase per object, as goals will name them
    cameras: Mapping[str, str] = {}  # Table 1 role (front, left, tilted) -> the env's camera name
    bodies: Mapping[str, str] = {}  # PRIVILEGED, optional: phrase -> the MuJoCo body whose position is the object's
    object_width: float = 0.06  # a typical object's width in metres (the labeler's pixel scale)
    table_height: float | None = None  # world z (metres) of the surface the objects rest on: the labeler reads the tilted camera on it in metres; None: in pixels
    subsets: bool | None = None  # the env can hold any subset of the objects (None: yes with an env_id, or a bare XML whose bodies are named)

    @property
    def name(self) -> str:
        """How messages and dataset manifests name this adapter: ``module:Class``."""
        return f"{type(self).__module__}:{type(self).__qualname__}"

    @property
    def holds_subsets(self) -> bool:
        """Can a scene hold only some of the objects (exploration scenes with fewer of them)? A bare
        XML can when :attr:`bodies` names each object's body: zsrm parks the others away."""
        if self.subsets is not None:
            return bool(self.subsets)
        return bool(self.env_id) or bool(self.xml and self.bodies)

    @property
    def roles(self) -> dict[str, str]:
        """Role -> the env's camera name, in Table 1's order."""
        return {role: self.cameras[role] for role in ROLES if role in self.cameras}

    def env_objects(self, phrases: tuple[str, ...]):
        """What the env's ``objects`` keyword takes for these phrases (default: the phrases)."""
        return tuple(phrases)

    def make_env(self, cameras: tuple[str, ...], image_size: int = 64, objects: tuple[str, ...] | None = None,
                 task: bool = False) -> gym.Env:
        """An env observing ``cameras`` (the env's own camera names) at ``image_size``, holding
        ``objects`` (phrases; all of them when None or when the env cannot hold fewer). ``task``:
        a scene a policy trains or is evaluated in (``task_env_kwargs`` apply); else exploration."""
        env_kwargs = {**self.env_kwargs, **(self.task_env_kwargs if task else {})}
        if not self.env_id and self.xml:
            from zsrm.envs.xml_scene import XmlSceneEnv

            held = None
            if self.holds_subsets:
                if not self.bodies:
                    raise SceneAdapterError(f"{self.name}: a bare XML holds subsets of its objects only when bodies "
                                            "names each object's body (or set subsets = False)")
                held = tuple(self.bodies[p] for p in (self.objects if objects is None else objects))
            try:
                env = XmlSceneEnv(self.xml, cameras=tuple(cameras), image_size=int(image_size), objects=held,
                                  **env_kwargs)
            except ValueError as err:  # what the XML alone cannot do
                raise SceneAdapterError(f"{self.name}: {err}") from None
            return gym.wrappers.TimeLimit(env, max_episode_steps=100)  # zsrm's episodes (zsrm.envs.EPISODE_STEPS)
        if not self.env_id:
            raise SceneAdapterError(f"{self.name}: give env_id (a gymnasium id) or xml, or override make_env")
        kwargs = dict(env_kwargs, cameras=tuple(cameras), image_size=int(image_size))
        if self.holds_subsets:
            kwargs["objects"] = self.env_objects(tuple(self.objects if objects is None else objects))
        try:
            return gym.make(self.env_id, **kwargs)
        except gym.error.Error as err:  # an unknown or unregistered id
            raise SceneAdapterError(f"{self.name}: cannot make env {self.env_id!r}: {err}") from None

    def task_reset_options(self, goal) -> dict | None:
        """Options for the env's ``reset`` in a goal's training and evaluation scenes (None: none):
        how a scene starts for this goal, as zsrm's own task scenes start the gripper or pusher by
        the object the goal moves. ``goal`` has ``relation`` and ``objects`` (phrases, the moved
        object first). Only the start depends on it; the policy and the reward still see pixels."""
        return None

    def observe(self, observation) -> dict[str, np.ndarray]:
        """The env's observation -> ``{role: image}`` of the roles whose camera it holds."""
        return {role: observation[cam] for role, cam in self.roles.items() if cam in observation}

    def exploration_action(self, env: gym.Env, rng: np.random.Generator) -> np.ndarray:
        """An exploration action (paper 2.2: random actions): uniform over a bounded Box."""
        space = env.action_space
        if not (isinstance(space, gym.spaces.Box) and space.is_bounded()):
            raise SceneAdapterError(f"{self.name}: the env's actions are {space}, not a bounded Box: "
                                    "write exploration_action(env, rng)")
        return rng.uniform(space.low, space.high).astype(space.dtype)

    def object_positions(self, env: gym.Env) -> dict[str, np.ndarray]:
        """PRIVILEGED: the true world position (x, y, z) of every object the scene holds, keyed
        by phrase. Only the oracle, evaluation and the scene stand-in VLM's presence-caption
        pretraining call it; never a reward model or a policy. The default reads the positions of
        the bodies :attr:`bodies` names, every object's (for scenes that hold all of them)."""
        if not self.bodies:
            raise NotImplementedError(f"{self.name}: name each object's body in bodies, or write "
                                      "object_positions(env), the privileged accessor")
        base = env.unwrapped
        held = getattr(base, "held_bodies", None)  # a bare XML's scene of some of the objects
        return {p: base.data.xpos[mujoco.mj_name2id(base.model, mujoco.mjtObj.mjOBJ_BODY, b)].copy()
                for p, b in self.bodies.items() if held is None or b in held}


# --- checks ---------------------------------------------------------------------------------
def check_adapter(adapter: SceneAdapter) -> SceneAdapter:
    """What can be checked before an env exists: roles, phrases, sizes, the XML's cameras."""
    if not isinstance(adapter, SceneAdapter):
        raise SceneAdapterError(f"{type(adapter).__name__} is not a zsrm.envs.SceneAdapter")
    _check_roles(adapter)
    _check_phrases(adapter)
    if not (isinstance(adapter.object_width, (int, float)) and adapter.object_width > 0):
        raise SceneAdapterError(f"{adapter.name}: object_width must be a positive number of metres, "
                                f"got {adapter.object_width!r}")
    if adapter.table_height is not None and not isinstance(adapter.table_height, (int, float)):
        raise SceneAdapterError(f"{adapter.name}: table_height must be a height in metres (world z) or None, "
                                f"got {adapter.table_height!r}")
    if adapter.bodies and set(adapter.bodies) != set(adapter.objects):
        raise SceneAdapterError(f"{adapter.name}: bodies must name a body for each object and only those; "
                                f"objects: {', '.join(adapter.objects)}; bodies: {', '.join(adapter.bodies)}")
    if adapter.xml is not None:
        try:
            model = mujoco.MjModel.from_xml_path(str(adapter.xml))
        except ValueError as err:
            raise SceneAdapterError(f"{adapter.name}: cannot load xml {adapter.xml}: "
                                    f"{str(err).splitlines()[0] if str(err) else err}") from None
        check_model_cameras(adapter, model)
        check_model_bodies(adapter, model)
    return adapter


def _check_roles(adapter: SceneAdapter) -> None:
    cams = adapter.cameras
    if not isinstance(cams, Mapping):
        raise SceneAdapterError(f"{adapter.name}: cameras must map roles to camera names, got {cams!r}")
    for role, cam in cams.items():
        if role not in ROLES:
            raise SceneAdapterError(f"{adapter.name}: unknown camera role {role!r}; the roles are "
                                    f"{', '.join(ROLES)} (Table 1)")
        if not isinstance(cam, str) or not cam:
            raise SceneAdapterError(f"{adapter.name}: the {role!r} role needs a camera name, got {cam!r}")
    for role in ROLES:
        if role not in cams:
            raise SceneAdapterError(f"{adapter.name}: no camera plays the {role!r} role; give cameras = "
                                    + "{" + ", ".join(f"{r!r}: ..." for r in ROLES) + "}")
    seen: dict[str, str] = {}
    for role, cam in adapter.roles.items():
        if cam in seen:
            raise SceneAdapterError(f"{adapter.name}: the {seen[cam]!r} and {role!r} roles are both camera "
                                    f"{cam!r}; each role needs its own view")
        seen[cam] = role


def _check_phrases(adapter: SceneAdapter) -> None:
    objects = adapter.objects
    if isinstance(objects, str) or not isinstance(objects, (tuple, list)) or not objects:
        raise SceneAdapterError(f"{adapter.name}: objects must be a tuple of noun phrases "
                                f"(e.g. ('red mug', 'blue plate')), got {objects!r}")
    for phrase in objects:
        if not isinstance(phrase, str) or not _PHRASE.match(phrase):
            raise SceneAdapterError(f"{adapter.name}: object {phrase!r} is not a noun phrase of lower-case "
                                    "words (e.g. 'red mug')")
    dup = sorted({p for p in objects if list(objects).count(p) > 1})
    if dup:
        raise SceneAdapterError(f"{adapter.name}: objects must differ, {', '.join(map(repr, dup))} "
                                "is named more than once")


def check_phrases_known(adapter: SceneAdapter, phrases) -> tuple[str, ...]:
    """``phrases`` (a choice among the adapter's objects), or a one-line error naming the unknown."""
    phrases = tuple(phrases)
    for p in phrases:
        if p not in adapter.objects:
            raise SceneAdapterError(f"{adapter.name}: unknown object {p!r}; this scene's objects: "
                                    f"{', '.join(adapter.objects)}")
    return phrases


def check_model_cameras(adapter: SceneAdapter, model: mujoco.MjModel) -> None:
    """Every role's camera is a camera of the MuJoCo model."""
    names = [model.camera(i).name for i in range(model.ncam)]
    for role, cam in adapter.roles.items():
        if cam not in names:
            raise SceneAdapterError(f"{adapter.name}: the {role!r} role's camera {cam!r} is not a camera of "
                                    f"the model; its cameras: {', '.join(names) or 'none'}")


def check_model_bodies(adapter: SceneAdapter, model: mujoco.MjModel) -> None:
    """Every body :attr:`SceneAdapter.bodies` names is a body of the MuJoCo model."""
    for phrase, body in adapter.bodies.items():
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, body) < 0:
            raise SceneAdapterError(f"{adapter.name}: the body {body!r} of {phrase!r} is not a body of the model")


def check_env(adapter: SceneAdapter, env: gym.Env, roles=ROLES) -> gym.Env:
    """An env of the adapter: its MuJoCo model has the roles' cameras (MuJoCo envs are the
    ones whose true pixels zsrm can compute), and it observes the camera of each of ``roles``
    (all three by default) as an image."""
    model = getattr(env.unwrapped, "model", None)
    if not isinstance(model, mujoco.MjModel):
        raise SceneAdapterError(f"{adapter.name}: {type(env.unwrapped).__name__} has no MuJoCo model "
                                "(env.unwrapped.model): zsrm projects true positions through its cameras")
    check_model_cameras(adapter, model)
    check_model_bodies(adapter, model)
    space = env.observation_space
    if not isinstance(space, gym.spaces.Dict):
        raise SceneAdapterError(f"{adapter.name}: the env observes {space}, not camera images; zsrm reads "
                                "pixels only: observe a dict {camera name: (H, W, 3) uint8 image}")
    for role in roles:
        cam = adapter.roles[role]
        box = space.spaces.get(cam)
        if box is None or box.dtype != np.uint8 or len(box.shape) != 3 or box.shape[-1] != 3:
            got = "nothing" if box is None else f"{box}"
            raise SceneAdapterError(f"{adapter.name}: the env observes {got} for camera {cam!r} (the {role!r} "
                                    "role), not an (H, W, 3) uint8 image: it cannot render that camera")
    return env


# --- loading --------------------------------------------------------------------------------
_REGISTRY: dict[str, "str | type[SceneAdapter]"] = {}


def register_scene(scene_id: str, adapter: "str | type[SceneAdapter]") -> None:
    """Name an adapter (a class or a ``module:Class`` string) with a short id."""
    if not isinstance(scene_id, str) or not scene_id or ":" in scene_id:
        raise SceneAdapterError(f"a scene id is a non-empty name without ':', got {scene_id!r}")
    _REGISTRY[scene_id] = adapter


def registered_scenes() -> dict[str, "str | type[SceneAdapter]"]:
    """Ids of :func:`register_scene` and of the ``zsrm.scenes`` entry points."""
    found: dict = {ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)}
    return {**found, **_REGISTRY}


def _import_class(spec: str):
    module, _, qualname = spec.partition(":")
    if not module or not qualname:
        raise SceneAdapterError(f"scene {spec!r}: give module:Class (e.g. mylab.scenes:MugsAdapter) or a "
                                f"registered id ({', '.join(registered_scenes()) or 'none registered'})")
    if os.getcwd() not in sys.path and "" not in sys.path:  # the current folder, as with python -m
        sys.path.append(os.getcwd())
    try:
        obj = importlib.import_module(module)
    except ImportError as err:
        raise SceneAdapterError(f"scene {spec!r}: cannot import {module!r} ({err})") from None
    for part in qualname.split("."):
        if not hasattr(obj, part):
            raise SceneAdapterError(f"scene {spec!r}: module {module!r} has no {qualname!r}")
        obj = getattr(obj, part)
    return obj


def load_adapter(scene: "str | SceneAdapter | type[SceneAdapter]") -> SceneAdapter:
    """The checked adapter that ``scene`` names: an instance, a class, a registered id, or
    ``module:Class``."""
    if isinstance(scene, str):
        target = registered_scenes().get(scene, scene)
        scene = _import_class(target) if isinstance(target, str) else target
    if isinstance(scene, type):
        if not issubclass(scene, SceneAdapter):
            raise SceneAdapterError(f"{scene.__module__}:{scene.__qualname__} is not a zsrm.envs.SceneAdapter "
                                    "subclass")
        scene = scene()
    return check_adapter(scene)


__all__ = ["ROLES", "SceneAdapter", "SceneAdapterError", "check_adapter", "check_env", "check_model_bodies",
           "check_model_cameras", "check_phrases_known", "load_adapter", "register_scene", "registered_scenes"]
