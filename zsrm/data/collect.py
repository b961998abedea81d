"""Random exploration data (paper 2.2): random initial arm and object positions, random actions,
every camera, seeded, written in shards with a manifest and resumable after a kill.

Each image comes with what only evaluation may read: the objects' true world positions and
their true pixel coordinates on each camera.

With ``p_box`` some tabletop scenes also hold the open box ("inside of" needs it), in about
half of them with a block dropped into it at the reset. The box is stored apart from the
colours (``box_present``, ``box_position``, ``box_pixels_<camera>``, only in datasets collected
with ``p_box``), so the colour arrays keep their shape and meaning in every dataset.

With ``scene`` (``zsrm collect --scene module:Class``), the data come from a user's own scene
through its :class:`zsrm.envs.SceneAdapter`: the same shards, keyed by Table 1's camera roles
(``images_front``, ...), with the adapter's object phrases in place of the colours (the
manifest's ``colours``). True positions come from the adapter's privileged accessor and, like
zsrm's own, are for evaluation only.

>>> import tempfile
>>> folder = tempfile.mkdtemp()
>>> data = collect(CollectConfig(images=4, shard_size=2, episode_steps=4, record_every=2), folder, progress=False)
>>> len(data), data.load(["images_front"])["images_front"].shape
(4, (4, 64, 64, 3))
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from zsrm.data.dataset import ExplorationData
from zsrm.data.shards import ShardFolder, save_npz
from zsrm.tasks.catalogue import SCENE_IDS
from zsrm.tasks.language import COLOURS
from zsrm.tasks.lexicon import BOX
from zsrm.tasks.relations import CAMERAS, TABLE_PLANE_CAMERAS

# Box scenes whose reset drops a block into the box: random actions almost never do, and a box
# that never holds a block teaches no "inside of".
P_BLOCK_IN_BOX = 0.5


@dataclass
class CollectConfig:
    """Options of ``zsrm collect``. The data depend on these and nothing else."""

    images: int = 1000  # images (per camera) in all
    shard_size: int = 100  # images per shard (the unit a killed run resumes from)
    seed: int = 0  # seed of the whole dataset; shard i uses (seed, i)
    scenes: tuple[str, ...] = ("tabletop",)  # scenes to explore: tabletop, pushing
    cameras: tuple[str, ...] = CAMERAS  # cameras to render
    image_size: int = 64  # image side in pixels
    min_objects: int = 2  # fewest objects in a scene
    max_objects: int = 4  # most objects in a scene
    exclude: tuple[str, ...] = ()  # colours never to place (the multi-task data never sees blue)
    episode_steps: int = 20  # random actions per episode
    record_every: int = 5  # keep the images of every this many steps, from the reset on
    p_stack: float = 0.25  # chance that a block starts stacked on another
    p_side: float = 0.25  # chance that an object starts beside another (near or touching)
    p_hold: float = 0.0  # tabletop: chance that the gripper starts holding a block above another
    p_hold_free: float = 0.0  # tabletop: of those, the chance that the block is held anywhere in reach, high above the others
    p_box: float = 0.0  # tabletop: chance that a scene also holds the open box (half of those with a block in it)
    scene: str = ""  # your own scene instead of --scenes: a SceneAdapter as module:Class or a registered id (docs/own-scene.md)
    colours: tuple[str, ...] = field(init=False)

    def __post_init__(self):
        for name in ("images", "shard_size", "image_size", "episode_steps", "record_every"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value < 1:
                raise ValueError(f"{name} must be a positive integer, got {value!r}")
        for name in ("p_stack", "p_side", "p_hold", "p_hold_free", "p_box"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be a probability in [0, 1], got {getattr(self, name)!r}")
        self.scenes, self.cameras, self.exclude = tuple(self.scenes), tuple(self.cameras), tuple(self.exclude)
        self._adapter = self._user_scene() if self.scene else None
        for s in self.scenes:
            if s not in SCENE_IDS and not self.scene:
                raise ValueError(f"unknown scene {s!r}; known scenes: {', '.join(SCENE_IDS)}")
        if not self.scenes:
            raise ValueError("give at least one scene")
        for c in self.cameras:
            if c not in CAMERAS:
                raise ValueError(f"unknown camera {c!r}; known cameras: {', '.join(CAMERAS)}")
        for c in self.exclude:
            if c not in self.objects:
                raise ValueError(f"unknown {'object' if self.scene else 'colour'} {c!r} to exclude; known: "
                                 f"{', '.join(self.objects)}")
        self.colours = tuple(c for c in self.objects if c not in self.exclude)
        if self.scene:  # an own scene of fewer objects than the defaults' 2..4: its scenes hold up to all of them
            self.max_objects = min(self.max_objects, len(self.colours))
            self.min_objects = min(self.min_objects, self.max_objects)
        if not 1 <= self.min_objects <= self.max_objects <= len(self.colours):
            raise ValueError(f"need 1 <= min_objects <= max_objects <= {len(self.colours)} "
                             f"(colours left: {', '.join(self.colours)}), got {self.min_objects}..{self.max_objects}")

    def _user_scene(self):
        """The adapter that ``scene`` names; the dataset's one scene is then the adapter's name."""
        from zsrm.envs.adapter import load_adapter

        if not isinstance(self.scene, str):  # the manifest records it: a name, not an object
            raise ValueError(f"scene must be module:Class or a registered id, got {type(self.scene).__name__}; "
                             "name an adapter class with zsrm.envs.register_scene")
        if self.scenes not in (("tabletop",), (self.scene,)):
            raise ValueError(f"give --scene (your own scene) or --scenes (zsrm's: {', '.join(SCENE_IDS)}), not both")
        if self.p_hold or self.p_hold_free or self.p_box:
            raise ValueError("--p-hold, --p-hold-free and --p-box are for zsrm's tabletop, not for your own scene")
        adapter = load_adapter(self.scene)
        self.scenes = (self.scene,)
        return adapter

    @property
    def adapter(self):
        """The own scene's :class:`zsrm.envs.SceneAdapter` (None for zsrm's scenes)."""
        return self._adapter

    @property
    def objects(self) -> tuple[str, ...]:
        """Every object the data can hold (the arrays' K): zsrm's colours, or the adapter's phrases."""
        return tuple(self._adapter.objects) if self._adapter is not None else COLOURS

    @property
    def n_shards(self) -> int:
        return -(-self.images // self.shard_size)

    def to_json(self) -> dict:
        d = asdict(self)
        d.pop("colours")
        # added later: datasets collected before them keep matching their manifest
        for name in ("p_hold", "p_hold_free", "p_box", "scene"):
            if not d[name]:
                d.pop(name)
        return d


class _Envs:
    """One env per (scene, colour set), made on first use (the colour set fixes the model)."""

    def __init__(self, cfg: CollectConfig):
        self.cfg, self.envs = cfg, {}

    def get(self, scene: str, colours: tuple[str, ...]):
        key = (scene, colours)
        if key not in self.envs and self.cfg.adapter is not None:
            from zsrm.envs.adapter import check_env

            adapter = self.cfg.adapter
            env = adapter.make_env(tuple(adapter.roles[c] for c in self.cfg.cameras), self.cfg.image_size, colours)
            self.envs[key] = check_env(adapter, env, self.cfg.cameras)
        if key not in self.envs:
            import gymnasium as gym

            import zsrm.envs  # noqa: F401  (registers the ids)

            self.envs[key] = gym.make(SCENE_IDS[scene], task=None, objects=colours, cameras=self.cfg.cameras,
                                      image_size=self.cfg.image_size).unwrapped
        return self.envs[key]

    def close(self):
        for env in self.envs.values():
            env.close()
        self.envs.clear()


def block_widths(cfg: CollectConfig) -> dict[str, dict[str, float]]:
    """Width of one object in pixels, per scene and camera (the labeler's pixel scale)."""
    from zsrm.envs.cameras import object_width_px

    envs = _Envs(cfg)
    try:
        return {s: {c: object_width_px(envs.get(s, cfg.colours[:2]), c, cfg.image_size) for c in cfg.cameras}
                for s in cfg.scenes}
    finally:
        envs.close()


def table_homographies(cfg: CollectConfig) -> dict[str, dict[str, list]]:
    """Pixel -> table-metres maps of the table-plane cameras, per scene (calibration only)."""
    from zsrm.envs.cameras import table_homographies as of_env

    envs = _Envs(cfg)
    try:
        return {s: of_env(envs.get(s, cfg.colours[:2]), cfg.image_size, cfg.cameras) for s in cfg.scenes}
    finally:
        envs.close()


def camera_rays(cfg: CollectConfig) -> dict[str, dict]:
    """Per zsrm scene (calibration only): each camera's :func:`~zsrm.envs.cameras.pixel_rays`
    (``rays``), the height of a resting object's centre (``rest_z``) and an object's width (``width``), m."""
    from zsrm.envs.base import TABLE_TOP
    from zsrm.envs.cameras import pixel_rays

    if cfg.adapter is not None:
        raise ValueError("camera rays are read from zsrm's scenes, not an adapter's")
    envs = _Envs(cfg)
    try:
        return {s: {"rays": {c: pixel_rays(env, c, cfg.image_size) for c in cfg.cameras},
                    "rest_z": TABLE_TOP + env.rest_height, "width": 2 * env.object_half_size}
                for s in cfg.scenes for env in (envs.get(s, cfg.colours[:2]),)}
    finally:
        envs.close()


def collect_shard(cfg: CollectConfig, index: int, envs: _Envs | None = None) -> dict[str, np.ndarray]:
    """The arrays of shard ``index``: a function of ``cfg`` and ``index`` only."""
    from zsrm.envs.cameras import project

    if cfg.adapter is not None:
        return collect_own_shard(cfg, index, envs)
    own = envs is None
    envs = envs or _Envs(cfg)
    rng = np.random.default_rng([cfg.seed, index])
    n = _shard_len(cfg, index)
    out = _empty_shard(cfg, n)
    if cfg.p_box:  # only datasets that can hold the box have its arrays
        out.update(box_present=np.zeros(n, bool), box_position=np.full((n, 3), np.nan, np.float32))
        out.update({f"box_pixels_{c}": np.full((n, 2), np.nan, np.float32) for c in cfg.cameras})
    row, episode = 0, 0
    try:
        while row < n:
            scene = cfg.scenes[rng.integers(len(cfg.scenes))]
            n_obj = int(rng.integers(cfg.min_objects, cfg.max_objects + 1))
            chosen = set(rng.choice(cfg.colours, n_obj, replace=False).tolist())
            colours = tuple(c for c in COLOURS if c in chosen)
            # Drawn only when p_box is set: datasets without the box keep their random stream.
            with_box = scene == "tabletop" and bool(cfg.p_box) and rng.random() < cfg.p_box
            env = envs.get(scene, colours + (BOX,) if with_box else colours)
            options = {"p_stack": cfg.p_stack, "p_side": cfg.p_side}
            if scene == "tabletop" and cfg.p_hold:  # the only scene with a gripper that holds
                options["p_hold"] = cfg.p_hold
                if cfg.p_hold_free:
                    options["p_hold_free"] = cfg.p_hold_free
            if with_box:
                options["p_inside"] = P_BLOCK_IN_BOX
            obs, info = env.reset(seed=int(rng.integers(2**31 - 1)), options=options)
            for step in range(cfg.episode_steps):
                if step % cfg.record_every == 0 and row < n:
                    for cam in cfg.cameras:
                        out[f"images_{cam}"][row] = obs[cam]
                    for colour, xyz in info["object_positions"].items():
                        if colour == BOX:
                            _record_box(out, row, env, xyz, cfg)
                            continue
                        i = COLOURS.index(colour)
                        out["positions"][row, i] = xyz
                        out["present"][row, i] = True
                        for cam in cfg.cameras:
                            out[f"pixels_{cam}"][row, i] = project(env, cam, xyz, cfg.image_size)
                    out["scene"][row] = cfg.scenes.index(scene)
                    out["episode"][row], out["step"][row] = episode, step
                    row += 1
                action = rng.uniform(-1.0, 1.0, env.action_space.shape).astype(np.float32)
                obs, _, terminated, _, info = env.step(action)
                if terminated:  # an object fell off the table: a new episode
                    break
            episode += 1
    finally:
        if own:
            envs.close()
    return out


def _empty_shard(cfg: CollectConfig, n: int) -> dict[str, np.ndarray]:
    """The arrays of ``n`` images over every object the data can hold (NaN: not there)."""
    k = len(cfg.objects)
    out = {f"images_{c}": np.zeros((n, cfg.image_size, cfg.image_size, 3), np.uint8) for c in cfg.cameras}
    out.update({f"pixels_{c}": np.full((n, k, 2), np.nan, np.float32) for c in cfg.cameras})
    out.update(positions=np.full((n, k, 3), np.nan, np.float32), present=np.zeros((n, k), bool),
               scene=np.zeros(n, np.int8), episode=np.zeros(n, np.int32), step=np.zeros(n, np.int16))
    return out


def collect_own_shard(cfg: CollectConfig, index: int, envs: _Envs | None = None) -> dict[str, np.ndarray]:
    """Shard ``index`` of a user's own scene (``cfg.scene``): random scenes of its objects (as
    many as the adapter's env can leave out), its exploration actions, every camera role. True
    positions come from the adapter's privileged accessor, for evaluation only."""
    own = envs is None
    envs = envs or _Envs(cfg)
    adapter = cfg.adapter
    rng = np.random.default_rng([cfg.seed, index])
    n = _shard_len(cfg, index)
    out, row, episode = _empty_shard(cfg, n), 0, 0
    try:
        while row < n:
            objects = cfg.objects
            if adapter.holds_subsets:
                chosen = set(rng.choice(cfg.colours, int(rng.integers(cfg.min_objects, cfg.max_objects + 1)),
                                        replace=False).tolist())
                objects = tuple(o for o in cfg.objects if o in chosen)
            env = envs.get(cfg.scene, objects)
            obs, _ = env.reset(seed=int(rng.integers(2**31 - 1)))
            for step in range(cfg.episode_steps):
                if step % cfg.record_every == 0 and row < n:
                    _record_own(out, row, cfg, env, obs)
                    out["episode"][row], out["step"][row] = episode, step
                    row += 1
                obs, _, terminated, truncated, _ = env.step(adapter.exploration_action(env, rng))
                if terminated or truncated:
                    break
            episode += 1
    finally:
        if own:
            envs.close()
    return out


def _record_own(out: dict, row: int, cfg: CollectConfig, env, obs) -> None:
    """One image per camera role, and (privileged, evaluation only) the objects' true positions
    and their projections through each role's camera."""
    from zsrm.envs.cameras import project

    adapter = cfg.adapter
    images = adapter.observe(obs)
    for role in cfg.cameras:
        out[f"images_{role}"][row] = images[role]
    from zsrm.envs.adapter import check_phrases_known

    positions = adapter.object_positions(env)
    check_phrases_known(adapter, positions)  # a key that is no phrase of the adapter: one line, not an IndexError
    for phrase, xyz in positions.items():
        i = cfg.objects.index(phrase)
        out["positions"][row, i] = xyz
        out["present"][row, i] = True
        for role in cfg.cameras:
            out[f"pixels_{role}"][row, i] = project(env, adapter.roles[role], xyz, cfg.image_size)


def _own_manifest(cfg: CollectConfig) -> dict:
    """What a dataset of a user's own scene records beside its shards: the objects, each role's
    camera, the adapter's object width and table height, and one object's width in pixels per
    role (the labeler's pixel scale). Where the adapter gives its ``table_height``, the width is
    measured where the tilted camera looks at the plane of an object's centre (the table plus
    half an object width), and the tilted camera's table calibration
    (:func:`zsrm.envs.cameras.table_homography`, from the camera's pose) maps onto that plane,
    and each role's pixel rays (:func:`~zsrm.envs.cameras.pixel_rays`) let the labeler triangulate:
    geometry only. Without it there is no calibration, and the width is measured at the
    objects' mean position after the first reset (the privileged accessor, read once here)."""
    from zsrm.envs.cameras import object_width_px, pixel_rays, table_homography

    adapter, envs = cfg.adapter, _Envs(cfg)
    try:
        env = envs.get(cfg.scene, cfg.objects)
        env.reset(seed=cfg.seed)
        table, centre, rays = {}, None, {}
        if adapter.table_height is not None:
            height = adapter.table_height + adapter.object_width / 2
            table = {role: table_homography(env, adapter.roles[role], cfg.image_size, height).tolist()
                     for role in cfg.cameras if role in TABLE_PLANE_CAMERAS}
            rays = {role: pixel_rays(env, adapter.roles[role], cfg.image_size) for role in cfg.cameras}
            centre = _looked_at(env, adapter.roles["tilted"], height)
        if centre is None:
            centre = np.mean(list(adapter.object_positions(env).values()), axis=0)
        widths = {role: object_width_px(env, adapter.roles[role], cfg.image_size, adapter.object_width / 2, centre)
                  for role in cfg.cameras}
    finally:
        envs.close()
    return {"colours": list(cfg.objects), "block_width_px": {cfg.scene: widths}, "table_homography": {cfg.scene: table},
            **({"pixel_rays": {cfg.scene: rays}} if rays else {}),
            "scene_adapter": {"name": adapter.name, "env_id": adapter.env_id, "cameras": adapter.roles,
                              "object_width": adapter.object_width, "table_height": adapter.table_height}}


def _looked_at(env, camera: str, height: float) -> np.ndarray | None:
    """Where ``camera``'s view axis meets the horizontal plane at ``height`` (None if it does
    not look down onto it)."""
    from zsrm.envs.cameras import camera_frame

    pos, rot, _ = camera_frame(env, camera)
    view = -rot[:, 2]  # the camera looks down its -z axis
    if view[2] >= -1e-6 or pos[2] <= height:
        return None
    return pos + view * (height - pos[2]) / view[2]


def box_reference_point(xyz) -> np.ndarray:
    """The box's point whose projection is its true pixel centre: its centre at the height of a
    block's centre (a block in the box rests 4 mm above it), the height at which the tilted
    camera's table calibration maps pixels back to table metres exactly."""
    from zsrm.envs.base import TABLE_TOP
    from zsrm.envs.tabletop import BLOCK_HALF

    return np.array([xyz[0], xyz[1], TABLE_TOP + BLOCK_HALF])


def _record_box(out: dict, row: int, env, xyz, cfg: CollectConfig) -> None:
    from zsrm.envs.cameras import project

    out["box_present"][row] = True
    out["box_position"][row] = xyz
    for cam in cfg.cameras:
        out[f"box_pixels_{cam}"][row] = project(env, cam, box_reference_point(xyz), cfg.image_size)


def collect(cfg: CollectConfig, folder, progress: bool = True) -> ExplorationData:
    """Collect (or finish collecting) the dataset ``cfg`` describes into ``folder``."""
    from tqdm import tqdm

    extra = _own_manifest(cfg) if cfg.adapter is not None else {
        "colours": list(COLOURS), "block_width_px": block_widths(cfg), "table_homography": table_homographies(cfg)}
    shards = ShardFolder(folder, kind="exploration", config=cfg.to_json(), n_shards=cfg.n_shards, extra=extra)
    pending = shards.pending()
    bar = tqdm(total=cfg.images, initial=cfg.images - sum(_shard_len(cfg, i) for i in pending),
               unit="img", desc="collect", disable=not progress)
    envs = _Envs(cfg)
    try:
        for index in pending:
            arrays = collect_shard(cfg, index, envs)
            save_npz(shards.path(index, ".npz"), **arrays)
            shards.finish(index, {"images": len(arrays["scene"]), "seed": [cfg.seed, index]})
            bar.update(len(arrays["scene"]))
    finally:
        envs.close()
        bar.close()
    return ExplorationData(folder)


def _shard_len(cfg: CollectConfig, index: int) -> int:
    return min(cfg.shard_size, cfg.images - index * cfg.shard_size)
