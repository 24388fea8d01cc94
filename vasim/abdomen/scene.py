"""Abdomen scenes: organs, their physical parameters and motion, from ``protocols/scenes/*.toml``.

A scene file is parsed once into frozen, validated dataclasses (:class:`Scene`,
:class:`OrganConfig`, :class:`PhysicsConfig`, :class:`MotionConfig`); errors name the file, the
dotted field and the bad value. ``str(scene)`` is its fully resolved TOML, which loads back to
an equal scene. :meth:`Scene.build` turns it into mass-spring models, and :class:`ScenePhysics`
steps them all (one thread) with their anchors on the physiological motion.

TOML layout (every field is validated on load; defaults in brackets)::

    name = "default"                  # required
    description = "..."               # one line

    [physics]
    dt = 0.004                        # physics step [s], in (0, 0.02]  [0.004: 250 Hz]
    gravity = [0.0, 0.0, -9.81]       # [m/s²], scene frame (z up), magnitude <= 50
    tol = 0.01                        # relative tolerance of each implicit step  [0.01]
    cg_tol = 0.1                      # relative residual of each CG solve  [0.01]
    max_newton = 1                    # Newton iterations per organ and step  [4]
    max_iterations = 4                # CG iterations per organ and step  [100]
    preconditioner = "auto"           # "auto" | "diagonal" | "factor"  [auto]

    [motion]                          # scene-wide rates; amplitudes are per organ
    breathing_hz = 0.25               # in [0, 1], below 1/(2 dt)
    heartbeat_hz = 1.2                # in [0, 3], below 1/(2 dt)
    heart_centre = [0.0, 0.17, 0.05]  # [m] the heartbeat fades with the distance from here
    heart_falloff_m = 0.08            # Gaussian length scale [m]

    [organs.liver]                    # one table per organ, in drawing order
    mesh = "liver"                    # a procedural organ of vasim.abdomen.anatomy (default:
                                      # the table's name) or a mesh file (OBJ/STL/PLY/OFF),
                                      # relative to the scene file
    units = "m"                       # of a mesh file: "m" | "cm" | "mm"
    kind = "parenchyma"               # parenchyma | hollow | vessel | wall (procedural default)
    color = [0.48, 0.13, 0.10]
    delicate = false                  # contact counts as damage
    stiffness = 150.0                 # structural springs [N/m]
    bending_stiffness = 15.0          # springs across each edge [N/m]
    mass = 1.2                        # total [kg]
    damping = 0.02                    # per node [N s/m], toward the moving frame
    volume = true                     # interior nodes and spokes (volume preservation)
    volume_stiffness = 80.0           # [N/m]
    volume_spacing = 0.012            # [m] (default: twice the mean edge length)
    mass_distribution = "area"        # "area" | "uniform"
    kinematic = false                 # every node anchored (the abdominal wall; kind "wall"
                                      # must be kinematic; a scene needs one deformable organ)
    breathing_m = [0.0, 0.012, 0.0]   # breathing amplitude vector [m], each |.| <= 0.05
    heartbeat_m = [0.0, 0.0, 0.001]   # heartbeat amplitude at the heart centre [m], <= 0.01
    [[organs.liver.anchors]]          # anchored surface nodes: the union of these rules
                                      # (a deformable organ needs one per connected part)
    to = "plane"                      # "plane" | "point" | "wall"
    point = [0.0, 0.142, 0.0]
    normal = [0.0, -1.0, 0.0]
    fraction = 0.1                    # or: within = 0.005 [m]

Example:
    >>> scene = load_scene("default")
    >>> scene.physics.dt, [o.name for o in scene.organs][:2]
    (0.004, ['liver', 'stomach'])
    >>> parse_scene(str(scene)) == scene
    True
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from functools import cache
from pathlib import Path
from typing import Any

import trimesh

from vasim.abdomen import anatomy
from vasim.abdomen.integrate import OrganSolver, StepReport
from vasim.abdomen.meshes import UNIT_SCALE, load_user_mesh
from vasim.abdomen.model import (
    DEFAULT_GRAVITY,
    AnchorRule,
    FloatArray,
    OrganModel,
    OrganParams,
    OrganState,
    _number,
    _vec3,
    build_organ,
)
from vasim.abdomen.motion import (
    BREATHING_HZ,
    HEART_CENTRE,
    HEARTBEAT_HZ,
    Breathing,
    Heartbeat,
    PhysioMotion,
    PointMotion,
)
from vasim.core.bounds import (
    ANCHOR_DISTANCE_M,
    BREATHING_AMPLITUDE_M,
    BREATHING_RATE_HZ,
    COLOR_RGB,
    COORDINATE_M,
    DT_S,
    GRAVITY_M_S2,
    HEARTBEAT_AMPLITUDE_M,
    HEARTBEAT_RATE_HZ,
    SOLVER_ITERATIONS,
    Bound,
)
from vasim.core.config import (
    check_bool,
    check_choice,
    check_int,
    check_keys,
    check_str,
    check_table,
    check_type,
    expect,
    fail,
    parse_toml,
    rewrap,
)
from vasim.core.errors import ConfigError
from vasim.core.resources import data_file, read_data_file, scenes_dir

MAX_DT = DT_S.high
"""Largest physics step accepted [s] (the integrator is tested up to 16 ms)."""
KINDS = ("parenchyma", "hollow", "vessel", "wall")
# Plausibility bounds (**decision**: a value outside them is a typo, e.g. breathing
# amplitudes in mm where m are expected, which made the organ blow up and reset every step):
MAX_BREATHING_HZ = BREATHING_RATE_HZ.high
"""Fastest breathing accepted [Hz]: 60 breaths/min, above any tachypnoea (rest: 0.2-0.3 Hz)."""
MAX_HEARTBEAT_HZ = HEARTBEAT_RATE_HZ.high
"""Fastest heartbeat accepted [Hz]: 180 beats/min, above any heart rate under anaesthesia."""
MAX_BREATHING_M = BREATHING_AMPLITUDE_M.high
"""Largest breathing amplitude per axis [m]: the diaphragm moves organs by 1-3 cm, at most ~5 cm
in forced breathing."""
MAX_HEARTBEAT_M = HEARTBEAT_AMPLITUDE_M.high
"""Largest heartbeat amplitude per axis [m]: pulsation moves tissue by millimetres."""
MAX_GRAVITY = GRAVITY_M_S2.high
"""Largest gravity magnitude accepted [m/s²]: ~5 g; beyond, the value is not a gravity (a typo
or units error) and the settling/stepping would only blow up."""
GRAVITY_COMPONENT = Bound(-GRAVITY_M_S2.high, GRAVITY_M_S2.high, "m/s²", GRAVITY_M_S2.reason)
_NAME_RE = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]*$")
_TOP_FIELDS = ("name", "description", "physics", "motion", "organs")
_PHYSICS_FIELDS = ("dt", "gravity", "tol", "cg_tol", "max_newton", "max_iterations",
                   "preconditioner")
_MOTION_FIELDS = ("breathing_hz", "heartbeat_hz", "heart_centre", "heart_falloff_m")
_PARAM_FIELDS = tuple(f.name for f in fields(OrganParams) if f.name != "anchors")
_ORGAN_FIELDS = ("mesh", "units", "kind", "color", "delicate", *_PARAM_FIELDS, "breathing_m",
                 "heartbeat_m", "anchors")
_ANCHOR_FIELDS = ("to", "point", "normal", "within", "fraction")


@cache
def _procedural() -> dict[str, anatomy.Organ]:
    return {o.name: o for o in anatomy.default_anatomy()}


def procedural_names() -> tuple[str, ...]:
    """Names of the procedural organs a scene can use as ``mesh``."""
    return tuple(_procedural())


@dataclass(frozen=True)
class PhysicsConfig:
    """Physics of a scene.

    The solver fields are those of :class:`vasim.abdomen.integrate.SolverOptions`; a
    real-time scene bounds the work per step (one Newton step, a few CG iterations), the
    library defaults solve each step to ``tol``.

    Attributes:
        dt: physics step [s], in (0, :data:`MAX_DT`].
        gravity: (3,) [m/s²].
        tol: relative tolerance of each implicit step, in (0, 0.5].
        cg_tol: relative residual of each conjugate-gradient solve, in (0, 1).
        max_newton: Newton iterations per organ and step, >= 1.
        max_iterations: conjugate-gradient iterations per organ and step, >= 1.
        preconditioner: ``"auto"``, ``"diagonal"`` or ``"factor"``.
    """

    dt: float = 0.004
    gravity: tuple[float, float, float] = DEFAULT_GRAVITY
    tol: float = 0.01
    cg_tol: float = 0.01
    max_newton: int = 4
    max_iterations: int = 100
    preconditioner: str = "auto"

    def __post_init__(self) -> None:
        _number(self.dt, field_name="dt", low=0.0, low_open=True, bound=DT_S)
        object.__setattr__(self, "gravity", _vec3(self.gravity, field_name="gravity",
                                                  bound=GRAVITY_COMPONENT))
        g = math.sqrt(sum(c * c for c in self.gravity))
        expect(g <= MAX_GRAVITY, list(self.gravity),  # plausibility bound (MAX_GRAVITY)
                f"a magnitude <= {MAX_GRAVITY:g} m/s² (this one: {g:.3g} m/s²)",
                field="gravity")
        _number(self.tol, field_name="tol", low=0.0, low_open=True, high=0.5)
        _number(self.cg_tol, field_name="cg_tol", low=0.0, low_open=True, high=0.99)
        for name in ("max_newton", "max_iterations"):
            value = getattr(self, name)
            check_int(value, name, bound=SOLVER_ITERATIONS)
        check_choice(self.preconditioner, "preconditioner", ("auto", "diagonal", "factor"))

    @property
    def rate_hz(self) -> float:
        """Steps per simulated second."""
        return 1.0 / self.dt


@dataclass(frozen=True)
class MotionConfig:
    """Scene-wide rates of the physiological motion (amplitudes are per organ).

    Attributes:
        breathing_hz: [Hz], in [0, :data:`MAX_BREATHING_HZ`] (0: no breathing).
        heartbeat_hz: [Hz], in [0, :data:`MAX_HEARTBEAT_HZ`] (0: no heartbeat); both also
            below the Nyquist rate ``1 / (2 dt)`` of the physics step (checked by
            :class:`Scene`), else the motion aliases.
        heart_centre: (3,) [m]. heart_falloff_m: Gaussian length scale [m], > 0.
    """

    breathing_hz: float = BREATHING_HZ
    heartbeat_hz: float = HEARTBEAT_HZ
    heart_centre: tuple[float, float, float] = HEART_CENTRE
    heart_falloff_m: float = 0.08

    def __post_init__(self) -> None:
        _number(self.breathing_hz, field_name="breathing_hz", bound=BREATHING_RATE_HZ)
        _number(self.heartbeat_hz, field_name="heartbeat_hz", bound=HEARTBEAT_RATE_HZ)
        object.__setattr__(self, "heart_centre", _vec3(self.heart_centre,
                                                       field_name="heart_centre",
                                                       bound=COORDINATE_M))
        _number(self.heart_falloff_m, field_name="heart_falloff_m", low=0.0, low_open=True,
                bound=ANCHOR_DISTANCE_M)


@dataclass(frozen=True)
class OrganConfig:
    """One organ of a scene.

    Attributes:
        name: unique organ name.
        mesh: a procedural organ name (:func:`procedural_names`) or a mesh file path
            (absolute, or relative to the scene file: resolved on load).
        units: units of a mesh file.
        kind: tissue class; color: RGB in [0, 1]; delicate: contact counts as damage.
        params: physical parameters.
        breathing_m: (3,) breathing amplitude vector [m].
        heartbeat_m: (3,) heartbeat amplitude vector [m] at the heart centre.
    """

    name: str
    mesh: str
    units: str = "m"
    kind: str = "parenchyma"
    color: tuple[float, float, float] = (0.8, 0.4, 0.4)
    delicate: bool = False
    params: OrganParams = field(default_factory=OrganParams)
    breathing_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    heartbeat_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        _check_name(self.name)
        _check_mesh_ref(self.mesh, "mesh")
        check_choice(self.units, "units", tuple(UNIT_SCALE))
        check_choice(self.kind, "kind", KINDS)
        object.__setattr__(self, "color", _vec3(self.color, field_name="color", bound=COLOR_RGB))
        check_bool(self.delicate, "delicate")
        check_type(self.params, "params", OrganParams, "an OrganParams")
        object.__setattr__(self, "breathing_m", _vec3(self.breathing_m,
                                                      field_name="breathing_m",
                                                      bound=BREATHING_AMPLITUDE_M))
        object.__setattr__(self, "heartbeat_m", _vec3(self.heartbeat_m,
                                                      field_name="heartbeat_m",
                                                      bound=HEARTBEAT_AMPLITUDE_M))

    @property
    def is_procedural(self) -> bool:
        """The mesh is a procedural organ of :mod:`vasim.abdomen.anatomy`."""
        return self.mesh in _procedural()

    def motion(self, scene_motion: MotionConfig) -> PhysioMotion:
        """This organ's breathing and heartbeat under the scene-wide rates."""
        return PhysioMotion(
            Breathing(scene_motion.breathing_hz, self.breathing_m),
            Heartbeat(scene_motion.heartbeat_hz, self.heartbeat_m, scene_motion.heart_centre,
                      scene_motion.heart_falloff_m),
        )


@dataclass(frozen=True)
class Scene:
    """A validated abdomen scene (see the module docstring for the file layout).

    Attributes:
        name: scene name. description: one line.
        physics: step and solver settings. motion: scene-wide motion rates.
        organs: in drawing order, names unique.
        source: the file it was loaded from (not compared).
    """

    name: str
    description: str = ""
    physics: PhysicsConfig = PhysicsConfig()
    motion: MotionConfig = MotionConfig()
    organs: tuple[OrganConfig, ...] = ()
    source: str | None = field(default=None, compare=False, repr=False)

    def __post_init__(self) -> None:
        _check_name(self.name, self.source)
        check_str(self.description, "description", empty=True, file=self.source)
        organs = tuple(self.organs)
        seen = set()
        for o in organs:
            check_type(o, "organs", OrganConfig, "an OrganConfig", file=self.source)
            if o.name in seen:
                raise fail(o.name, f"an organ name not used before (duplicate organ name "
                           f"{o.name!r})", field=f"organs.{o.name}", file=self.source)
            seen.add(o.name)
        if not organs:
            raise fail(organs, "at least one organ", field="organs", file=self.source)
        # a scene of kinematic organs only validated, then a trial failed to bind
        # its targets ("no deformable organ"): at least one organ must deform.
        if all(o.params.kinematic for o in organs):
            raise fail([o.name for o in organs], "at least one deformable organ (kinematic = "
                       "false): every organ is kinematic", field="organs", file=self.source)
        # a kind="wall" organ is the kinematic wall (no contact, trocars fixed);
        # a deformable wall was never stepped, so it is refused rather than half-supported.
        for o in organs:
            if o.kind == "wall" and not o.params.kinematic:
                raise fail(False, 'true: an organ of kind "wall" must be kinematic (the wall '
                           'is not deformed)', file=self.source,
                           field=f"organs.{o.name}.kinematic")
        # a rate at or above the physics step's Nyquist rate aliases to nothing.
        nyquist = 0.5 / self.physics.dt
        for key in ("breathing_hz", "heartbeat_hz"):
            hz = getattr(self.motion, key)
            if hz >= nyquist:
                raise fail(hz, f"a rate below the Nyquist rate 1/(2 dt) = {nyquist:g} Hz of "
                           f"the physics step dt = {self.physics.dt:g} s",
                           field=f"motion.{key}", file=self.source)
        object.__setattr__(self, "organs", organs)

    def organ(self, name: str) -> OrganConfig:
        """The organ called ``name`` (KeyError otherwise)."""
        for o in self.organs:
            if o.name == name:
                return o
        raise KeyError(name)

    def motions(self) -> dict[str, PhysioMotion]:
        """Each organ's physiological motion, by name."""
        return {o.name: o.motion(self.motion) for o in self.organs}

    def solver_options(self) -> dict[str, Any]:
        """Keyword arguments of :class:`vasim.abdomen.integrate.OrganSolver`."""
        p = self.physics
        return {"tol": p.tol, "cg_tol": p.cg_tol, "max_newton": p.max_newton,
                "max_iterations": p.max_iterations, "preconditioner": p.preconditioner}

    def meshes(self) -> dict[str, trimesh.Trimesh]:
        """Each organ's surface [m] (procedural, or loaded and validated from its file).

        Raises:
            ConfigError: a user mesh is unusable (naming the mesh file and the field).
        """
        out = {}
        for o in self.organs:
            if o.is_procedural:
                out[o.name] = _procedural()[o.mesh].mesh.copy()
            else:
                out[o.name] = load_user_mesh(o.mesh, units=o.units,  # type: ignore[arg-type]  # o.mesh: a path here
                                             field=f"organs.{o.name}.mesh")
        return out

    def build(self) -> list[OrganModel]:
        """The mass-spring model of every organ, in drawing order.

        A kinematic organ (the abdominal wall) is a model whose nodes are all anchored: it
        moves only with its physiological motion. Anchor rules ``to = "wall"`` measure the
        distance to this scene's wall organ (``kind = "wall"``), else to the procedural wall.
        """
        meshes = self.meshes()
        wall = next((meshes[o.name] for o in self.organs if o.kind == "wall"), None)
        if wall is None:
            wall = _procedural()["abdominal_wall"].mesh
        models = []
        for o in self.organs:
            try:
                models.append(build_organ(meshes[o.name], o.params, name=o.name, kind=o.kind,
                                          color=o.color, delicate=o.delicate,
                                          gravity=self.physics.gravity, wall=wall))
            except ConfigError as exc:
                raise rewrap(exc, f"organs.{o.name}", self.source) from exc
        return models

    def __str__(self) -> str:
        return dumps_scene(self)


def _check_name(name: object, source: str | None = None) -> str:
    expect(isinstance(name, str) and _NAME_RE.match(name), name,
            "a name of letters, digits, '_', '-' or '.'", field="name", file=source)
    return str(name)


def _check_mesh_ref(mesh: object, field: str, source: str | None = None) -> str:
    return check_str(mesh, field, file=source, what="a procedural organ name or a file path")


# -- loading -----------------------------------------------------------------------------


def scene_path(ref: str | Path) -> Path:
    """The file of a scene given by name (``"default"``) or path."""
    p = Path(ref)
    if p.suffix == ".toml" or len(p.parts) > 1:
        return p
    return data_file(ref, scenes_dir(), "scene")


def load_scene(name_or_path: str | Path = "default") -> Scene:
    """Loads and validates a scene by name (``protocols/scenes/<name>.toml``) or path.

    Raises:
        ConfigError: naming the file, the dotted field and the value of the first problem
            (an unknown organ, a negative stiffness, a zero mass, a missing mesh file, ...).
    """
    path = scene_path(name_or_path)
    return parse_scene(read_data_file(path, "scene"), source=str(path))


def parse_scene(text: str, *, source: str = "<string>") -> Scene:
    """Parses and validates scene TOML text; ``source`` names it in errors and anchors
    relative mesh paths (its folder)."""
    return scene_from_dict(parse_toml(text, file=source, kind="scene"), source=source)


def _check_keys(table: Any, allowed: Sequence[str], path: str, source: str) -> dict[str, Any]:
    return check_keys(table, allowed, path, file=source)


def _build(cls: Any, kwargs: dict[str, Any], path: str, source: str) -> Any:
    try:
        return cls(**kwargs)
    except ConfigError as exc:
        raise rewrap(exc, path, source) from exc
    except TypeError as exc:
        raise ConfigError(str(exc), file=source, field=path) from exc


def scene_from_dict(data: Mapping[str, Any], *, source: str = "<dict>") -> Scene:
    """Builds a scene from parsed TOML (see the module docstring for the layout)."""
    top = check_keys(data, _TOP_FIELDS, "", file=source, required=("name",))
    physics = _build(PhysicsConfig, _check_keys(top.get("physics", {}), _PHYSICS_FIELDS,
                                                "physics", source), "physics", source)
    motion = _build(MotionConfig, _check_keys(top.get("motion", {}), _MOTION_FIELDS, "motion",
                                              source), "motion", source)
    organs_table = check_table(top.get("organs", {}), "organs", file=source,
                               what="a table of organ tables")
    base = Path(source).parent if source and not source.startswith("<") else Path.cwd()
    organs = [_organ(name, table, base, source) for name, table in organs_table.items()]
    return _build(Scene, {"name": top["name"], "description": top.get("description", ""),
                          "physics": physics, "motion": motion, "organs": tuple(organs),
                          "source": source}, "", source)


def _organ(name: str, table: Any, base: Path, source: str) -> OrganConfig:
    path = f"organs.{name}"
    t = _check_keys(table, _ORGAN_FIELDS, path, source)
    mesh = _check_mesh_ref(t.pop("mesh", name), f"{path}.mesh", source)
    procedural = _procedural()
    if mesh in procedural:
        organ = procedural[mesh]
        t.setdefault("kind", organ.kind)
        t.setdefault("color", list(organ.color))
        t.setdefault("delicate", organ.delicate)
    else:
        looks_like_file = Path(mesh).suffix != "" or "/" in mesh or "\\" in mesh
        expect(looks_like_file, mesh, f"a procedural organ ({', '.join(procedural)}) or a "
                "mesh file path (unknown organ mesh)", file=source, field=f"{path}.mesh")
        mesh_path = Path(mesh) if Path(mesh).is_absolute() else base / mesh
        expect(mesh_path.is_file(), mesh, f"an existing mesh file (mesh file not found: "
               f"{str(mesh_path)!r})", file=source, field=f"{path}.mesh")
        mesh = str(mesh_path.resolve())
    anchors_raw = check_type(t.pop("anchors", []), f"{path}.anchors", list,
                             f"an array of tables ([[{path}.anchors]])", file=source)
    anchors = []
    for i, a in enumerate(anchors_raw):
        apath = f"{path}.anchors[{i}]"
        anchors.append(_build(AnchorRule, _check_keys(a, _ANCHOR_FIELDS, apath, source), apath,
                              source))
    pkw = {k: t.pop(k) for k in _PARAM_FIELDS if k in t}
    params = _build(OrganParams, {**pkw, "anchors": tuple(anchors)}, path, source)
    return _build(OrganConfig, {"name": name, "mesh": mesh, "params": params, **t}, path, source)


# -- writing -----------------------------------------------------------------------------


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else "nan"
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, tuple | list):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise TypeError(f"cannot write {v!r} as TOML")


def dumps_scene(scene: Scene) -> str:
    """The scene as TOML: every field resolved (loads back to an equal :class:`Scene`)."""
    lines = [f"name = {_toml_value(scene.name)}",
             f"description = {_toml_value(scene.description)}", "", "[physics]"]
    for f in fields(PhysicsConfig):
        lines.append(f"{f.name} = {_toml_value(getattr(scene.physics, f.name))}")
    lines += ["", "[motion]"]
    for f in fields(MotionConfig):
        lines.append(f"{f.name} = {_toml_value(getattr(scene.motion, f.name))}")
    for o in scene.organs:
        lines += ["", f"[organs.{o.name}]", f"mesh = {_toml_value(o.mesh)}"]
        for key in ("units", "kind", "color", "delicate"):
            lines.append(f"{key} = {_toml_value(getattr(o, key))}")
        for key in _PARAM_FIELDS:
            value = getattr(o.params, key)
            if value is not None:
                lines.append(f"{key} = {_toml_value(value)}")
        lines.append(f"breathing_m = {_toml_value(o.breathing_m)}")
        lines.append(f"heartbeat_m = {_toml_value(o.heartbeat_m)}")
        for a in o.params.anchors:
            lines += ["", f"[[organs.{o.name}.anchors]]"]
            for key in _ANCHOR_FIELDS:
                value = getattr(a, key)
                if value is not None:
                    lines.append(f"{key} = {_toml_value(value)}")
    return "\n".join(lines) + "\n"


# -- stepping ----------------------------------------------------------------------------


class ScenePhysics:
    """Steps every organ of a scene once per call, in this thread, at the scene's ``dt``.

    Anchors follow ``rest + anchor_offsets(motion, rest, t + dt)``; each organ's damping pulls
    toward its motion's frame velocity. The contact hook is the ``forces`` argument of
    :meth:`step`: external forces per organ (e.g. from the tool), by name. A kinematic organ
    without motion (the default wall) is not stepped.

    Args:
        scene: the scene.
        models: its built models (default: ``scene.build()``).
        **solver_options: override the scene's solver options (``OrganSolver`` keywords).

    Example:
        >>> physics = ScenePhysics(load_scene("default"))
        >>> reports = physics.step()
        >>> all(r.ok for r in reports.values()), round(physics.t, 3)
        (True, 0.004)
    """

    def __init__(self, scene: Scene, models: Sequence[OrganModel] | None = None,
                 **solver_options: Any) -> None:
        self.scene = scene
        self.models = {m.name: m for m in (models if models is not None else scene.build())}
        options = {**scene.solver_options(), **solver_options}
        self.solvers = {name: OrganSolver(m, scene.physics.dt, **options)
                        for name, m in self.models.items()}
        self.motions = {name: scene.organ(name).motion(scene.motion) for name in self.models}
        self.states: dict[str, OrganState] = {name: s.initial_state()
                                              for name, s in self.solvers.items()}
        self.t = 0.0
        self._anchor_motion = {n: PointMotion(self.motions[n], m.rest[m.anchors])
                               for n, m in self.models.items()}
        self._node_motion = {n: PointMotion(self.motions[n], m.rest)
                             for n, m in self.models.items() if not self.motions[n].is_static}
        self._still = {n for n, m in self.models.items()
                       if self.motions[n].is_static and len(m.anchors) == m.n_nodes}
        for name in self.models:
            self.solvers[name].reset(self.states[name], self.anchor_targets(name, 0.0))

    @property
    def dt(self) -> float:
        return self.scene.physics.dt

    def anchor_targets(self, name: str, t: float) -> FloatArray:
        """(a, 3) anchor positions [m] of organ ``name`` at time ``t``."""
        am = self._anchor_motion[name]
        return am.points + am.offsets(t)

    def frame_velocity(self, name: str, t: float) -> FloatArray | None:
        """(n, 3) velocity of organ ``name``'s moving frame at ``t``, None when static."""
        nm = self._node_motion.get(name)
        return None if nm is None else nm.velocities(t)

    def step(self, forces: Mapping[str, FloatArray] | None = None) -> dict[str, StepReport]:
        """Advances every organ by ``dt``.

        Args:
            forces: external forces (n, 3) [N] by organ name (the contact hook); organs not
                named get none.

        Returns:
            The step report of every organ, by name.
        """
        t1 = self.t + self.dt
        forces = forces or {}
        reports = {}
        for name, solver in self.solvers.items():
            if name in self._still:
                self.states[name].t = t1
                reports[name] = StepReport(True, False, None, 0, 0, True, t1)
                continue
            reports[name] = solver.step(self.states[name], self.anchor_targets(name, t1),
                                        forces.get(name), v_frame=self.frame_velocity(name, t1))
        self.t = t1
        return reports

    def snapshot(self) -> dict[str, FloatArray]:
        """Copies of every organ's node positions (n, 3) [m], by name."""
        return {name: s.x.copy() for name, s in self.states.items()}


def with_organ(scene: Scene, organ: OrganConfig) -> Scene:
    """A copy of ``scene`` with ``organ`` replacing the organ of the same name (or added)."""
    organs = [organ if o.name == organ.name else o for o in scene.organs]
    if organ.name not in {o.name for o in scene.organs}:
        organs.append(organ)
    return replace(scene, organs=tuple(organs))


__all__ = [
    "KINDS",
    "MAX_BREATHING_HZ",
    "MAX_BREATHING_M",
    "MAX_DT",
    "MAX_GRAVITY",
    "MAX_HEARTBEAT_HZ",
    "MAX_HEARTBEAT_M",
    "MotionConfig",
    "OrganConfig",
    "PhysicsConfig",
    "Scene",
    "ScenePhysics",
    "dumps_scene",
    "load_scene",
    "parse_scene",
    "procedural_names",
    "scene_from_dict",
    "scene_path",
    "scenes_dir",
    "with_organ",
]
