"""Set-up files: a TOML description of geometry, materials, boundaries, initial
conditions and time, built into a :class:`sphjax.Case`.

    case = sphjax.cases.from_toml("examples/dam_break.toml")           # or
    case = sphjax.cases.from_toml("examples/dam_break.toml", dx=0.02)  # another resolution

The keys are described in docs/setups.md.  A file is read completely and checked before
anything is built: an unknown key (with the closest known one suggested), a missing one, a
value of the wrong type or out of range, a shape that does not fit the dimension, bodies that
overlap, all raise :class:`SetupError` whose message starts with the key, e.g.
``fluid.shapes[0].radius: must be a positive number, got -1``.

Particles are the lattice sites of :mod:`sphjax.geometry` (one lattice of spacing ``dx`` for
every body), in the blocks the systems own: fluid, walls, then solid and clamped particles,
then a rigid body's.
Fluid particles have mass ``rho0 dx^d``; with ``hydrostatic = true`` their initial density is
that of the pressure ``rho0 |g| depth`` (the equation of state inverted), the depth measured
against gravity from the top of each particle's own shape.  Solid particles have volume
``dx^d`` and mass ``rho dx^d``, a rigid body's too.  The initial state follows the Params
(``case.state_for(params)``), as the built-in cases' do.
"""

from __future__ import annotations

import difflib
import math
import tomllib
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from sphjax import geometry
from sphjax.core.case import Case
from sphjax.core.kernels import KERNELS, kernel_by_name
from sphjax.core.model import Domain, Model
from sphjax.core.params import make_params
from sphjax.core.state import Kind, make_state
from sphjax.integration.timestep import (
    FLUID_CFL,
    SOLID_CFL,
    check_time_step,
    split_substeps,
    stable_time_step,
)
from sphjax.physics.boundary.system import WallSystem
from sphjax.physics.boundary.wall import AdamiBoundary
from sphjax.physics.fluid.density import ContinuityDensity, SummationDensity
from sphjax.physics.fluid.density_diffusion import MolteniColagrossi
from sphjax.physics.fluid.eos import LinearEOS, TaitEOS
from sphjax.physics.fluid.momentum import TransportVelocity
from sphjax.physics.fluid.system import FluidSystem
from sphjax.physics.fluid.viscosity import ArtificialViscosity, MorrisViscosity
from sphjax.physics.rigid.contact import WallContact
from sphjax.physics.rigid.system import RigidSystem
from sphjax.physics.solid.boundary import SolidBoundary
from sphjax.physics.solid.penalty import PenaltyForce
from sphjax.physics.solid.system import SolidSystem


class SetupError(ValueError):
    """A bad set-up file; ``key`` is the dotted key (``fluid.shapes[0].radius``) or ``None``."""

    def __init__(self, key: str | None, message: str):
        super().__init__(message if not key else f"{key}: {message}")
        self.key = key


_REQUIRED = object()

SHAPE_KEYS = {
    "rectangle": ("lower", "upper"),
    "box": ("lower", "upper"),
    "circle": ("centre", "radius"),
    "sphere": ("centre", "radius"),
    "cylinder": ("base", "axis", "radius", "length"),
    "polygon": ("vertices",),
    "stl": ("file", "scale", "translate"),
}
SHAPE_DIM = dict(rectangle=2, circle=2, polygon=2, box=3, sphere=3, cylinder=3, stl=3)
WALL_SIDES = ("outside", "inside", "fill")
TOP_KEYS = (
    "name", "dim", "dx", "kernel", "h_factor", "gravity", "lattice_origin",
    "time", "fluid", "walls", "solid", "rigid", "domain",
)  # fmt: skip


class _Table:
    """Reads one TOML table: each ``get`` names a known key; ``done`` rejects the rest."""

    def __init__(self, table, where: str):
        if not isinstance(table, dict):
            raise SetupError(where, f"must be a table (a [{where}] section), got {table!r}")
        self.table, self.where, self.known = table, where, []

    def key(self, name: str) -> str:
        return f"{self.where}.{name}" if self.where else name

    def get(self, name: str, kind: str, default=_REQUIRED, **how):
        self.known.append(name)
        if name not in self.table:
            if default is _REQUIRED:
                # a misspelt key is the likelier mistake than a forgotten one
                others = [k for k in self.table if k not in self.known]
                for close in difflib.get_close_matches(name, others, n=1, cutoff=0.6):
                    raise SetupError(self.key(close), f"unknown key; did you mean '{name}'?")
                hint = how.get("hint", "")
                raise SetupError(self.key(name), f"missing; add it{hint}")
            return default
        return _convert(self.key(name), self.table[name], kind, **how)

    def done(self):
        for name in self.table:
            if name not in self.known:
                close = difflib.get_close_matches(name, self.known, n=1, cutoff=0.6)
                hint = (
                    f"did you mean '{close[0]}'?"
                    if close
                    else f"the keys here are {', '.join(self.known)}"
                )
                raise SetupError(self.key(name), f"unknown key; {hint}")


def _number(key, value, *, positive=False, non_negative=False, integer=False):
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise SetupError(key, f"must be a number, got {value!r}")
    if not math.isfinite(value):
        raise SetupError(key, f"must be a finite number, got {value!r}")
    if integer and not float(value).is_integer():
        raise SetupError(key, f"must be a whole number, got {value!r}")
    if positive and not value > 0:
        raise SetupError(key, f"must be a positive number, got {value!r}")
    if non_negative and value < 0:
        raise SetupError(key, f"must be a number >= 0, got {value!r}")
    return int(value) if integer else float(value)


def _convert(key, value, kind, *, choices=None, length=None, hint="", **number):
    if kind == "number":
        return _number(key, value, **number)
    if kind == "bool":
        if not isinstance(value, bool):
            raise SetupError(key, f"must be true or false, got {value!r}")
        return value
    if kind == "string":
        if not isinstance(value, str):
            raise SetupError(key, f"must be a string in quotes, got {value!r}")
        if choices is not None and value not in choices:
            close = difflib.get_close_matches(value, choices, n=1)
            mean = f"did you mean '{close[0]}'? " if close else ""
            raise SetupError(
                key, f"unknown value {value!r}; {mean}choose one of {', '.join(choices)}"
            )
        return value
    if kind == "vector":
        if not isinstance(value, list) or (length is not None and len(value) != length):
            size = f"{length} numbers (one per axis)" if length else "a list of numbers"
            raise SetupError(key, f"must be {size}, e.g. [{', '.join(['0.0'] * (length or 2))}]")
        return tuple(_number(f"{key}[{i}]", v, **number) for i, v in enumerate(value))
    if kind == "bools":
        if not isinstance(value, list) or len(value) != length:
            raise SetupError(key, f"must be {length} values true/false (one per axis)")
        for i, v in enumerate(value):
            if not isinstance(v, bool):
                raise SetupError(f"{key}[{i}]", f"must be true or false, got {v!r}")
        return tuple(value)
    if kind == "tables":
        if not isinstance(value, list) or not value or not all(isinstance(v, dict) for v in value):
            raise SetupError(
                key, f"must be a non-empty list of shapes, e.g. [[{key}]] sections{hint}"
            )
        return value
    raise AssertionError(kind)


# ---------------------------------------------------------------------------- reading


def _shape(table: _Table, dim: int, folder: Path):
    """The shape described by ``table`` (its ``shape`` key and that shape's keys)."""
    name = table.get("shape", "string", choices=tuple(SHAPE_KEYS))
    if SHAPE_DIM[name] != dim:
        other = {"rectangle": "box", "box": "rectangle", "circle": "sphere", "sphere": "circle"}
        fix = f"; use '{other[name]}'" if name in other else ""
        raise SetupError(table.key("shape"), f"a {name} is {SHAPE_DIM[name]}D but dim = {dim}{fix}")
    try:
        if name in ("rectangle", "box"):
            lower = table.get("lower", "vector", length=dim)
            upper = table.get("upper", "vector", length=dim)
            for i, (lo, hi) in enumerate(zip(lower, upper, strict=True)):
                if not hi > lo:
                    raise SetupError(
                        table.key("upper"), f"[{i}] = {hi:g} must exceed lower[{i}] = {lo:g}"
                    )
            return geometry.Box(lower, upper)
        if name in ("circle", "sphere"):
            centre = table.get("centre", "vector", length=dim)
            return geometry.Sphere(centre, table.get("radius", "number", positive=True))
        if name == "cylinder":
            base = table.get("base", "vector", length=3)
            axis = table.get("axis", "vector", length=3)
            if not any(axis):
                raise SetupError(table.key("axis"), "must be a non-zero direction, e.g. [0, 0, 1]")
            radius = table.get("radius", "number", positive=True)
            length = table.get("length", "number", positive=True)
            return geometry.Cylinder(base, axis, radius, length)
        if name == "polygon":
            table.known.append("vertices")
            vertices = table.table.get("vertices")
            if (
                not isinstance(vertices, list)
                or len(vertices) < 3
                or not all(isinstance(v, list) and len(v) == 2 for v in vertices)
            ):
                raise SetupError(
                    table.key("vertices"),
                    "must be a list of at least 3 [x, y] pairs, e.g. [[0, 0], [1, 0], [0, 1]]",
                )
            for i, v in enumerate(vertices):
                _convert(table.key(f"vertices[{i}]"), v, "vector", length=2)
            try:
                return geometry.Polygon(vertices)
            except ValueError as err:
                raise SetupError(
                    table.key("vertices"), str(err).removeprefix("vertices ")
                ) from None
        # stl
        file = table.get("file", "string", hint=" (the STL file, relative to the set-up file)")
        scale = table.get("scale", "number", 1.0, positive=True)
        translate = table.get("translate", "vector", (0.0, 0.0, 0.0), length=3)
        path = folder / file
        try:
            mesh = geometry.Mesh.from_stl(path)
        except ValueError as err:
            raise SetupError(table.key("file"), str(err)) from None
        if scale != 1.0 or any(translate):
            moved = mesh.mesh.copy()
            moved.apply_scale(scale)
            moved.apply_translation(translate)
            mesh = geometry.Mesh(moved, name=mesh.name)
        return mesh
    except ValueError as err:
        if isinstance(err, SetupError):
            raise
        raise SetupError(table.where, str(err)) from None


def _shapes(section: _Table, key: str, dim, folder, extra=None, required=True):
    """``[(shape, options), ...]`` of the ``[[section.key]]`` list; ``extra(table)`` reads
    per-shape options."""
    default = _REQUIRED if required else []
    entries = section.get(key, "tables", default, hint=" with shape = 'rectangle', ...")
    out = []
    for i, entry in enumerate(entries):
        table = _Table(entry, f"{section.key(key)}[{i}]")
        options = extra(table) if extra else {}
        shape = _shape(table, dim, folder)
        table.done()
        out.append((shape, options))
    return out


def read_setup(path) -> dict:
    """Parse and check a set-up file; returns its values (used by :func:`from_toml`)."""
    path = Path(path)
    if not path.is_file():
        raise SetupError(None, f"'{path}' does not exist (give the path of a .toml set-up file)")
    try:
        raw = tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise SetupError(None, f"not valid TOML: {err}") from None
    except (OSError, UnicodeDecodeError) as err:
        raise SetupError(None, f"cannot read '{path}': {err}") from None
    folder = path.parent
    top = _Table(raw, "")
    top.known = list(TOP_KEYS)
    top.done()  # a misspelt section is reported before what it lacks
    top.known = []
    s = dict(path=str(path))
    s["name"] = top.get("name", "string", path.stem)
    s["dim"] = top.get("dim", "number", integer=True, hint=" (dim = 2 or dim = 3)")
    if s["dim"] not in (2, 3):
        raise SetupError("dim", f"must be 2 or 3, got {s['dim']}")
    dim = s["dim"]
    s["dx"] = top.get("dx", "number", positive=True, hint=" (the particle spacing in m)")
    s["kernel"] = top.get("kernel", "string", "wendland_c2", choices=tuple(KERNELS))
    s["h_factor"] = top.get("h_factor", "number", 1.5, positive=True)
    s["gravity"] = top.get("gravity", "vector", (0.0,) * dim, length=dim)
    s["origin"] = top.get("lattice_origin", "vector", (0.0,) * dim, length=dim)

    top.known.append("time")
    if "time" not in raw:
        raise SetupError("time", "missing; add a [time] section with t_end = ... (in s)")
    time = _Table(raw["time"], "time")
    s["t_end"] = time.get("t_end", "number", positive=True, hint=" (the end time in s)")
    s["dt"] = time.get("dt", "number", None, positive=True)
    s["cfl"] = time.get("cfl", "number", None, positive=True)
    s["save_every"] = time.get("save_every", "number", None, positive=True, integer=True)
    s["save_dt"] = time.get("save_dt", "number", None, positive=True)
    time.done()
    if s["dt"] is not None and s["cfl"] is not None:
        raise SetupError("time.cfl", "give either time.dt or time.cfl, not both")
    if s["save_every"] is not None and s["save_dt"] is not None:
        raise SetupError("time.save_dt", "give either time.save_every or time.save_dt, not both")

    for name in ("fluid", "walls", "solid", "rigid", "domain"):
        top.known.append(name)
    s["fluid"] = _fluid(raw["fluid"], dim, folder) if "fluid" in raw else None
    s["walls"] = _walls(raw["walls"], dim, folder) if "walls" in raw else None
    s["solid"] = _solid(raw["solid"], dim, folder, "fluid" in raw) if "solid" in raw else None
    s["rigid"] = _rigid(raw["rigid"], dim, folder, "fluid" in raw) if "rigid" in raw else None
    s["domain"] = _domain(raw["domain"], dim) if "domain" in raw else None
    top.done()
    if s["walls"] is not None and s["fluid"] is None:
        raise SetupError("walls", "walls act on a fluid only; add a [fluid] section or remove it")
    if s["fluid"] is None and s["solid"] is None and s["rigid"] is None:
        raise SetupError(
            None, "the file describes no body; add a [fluid], a [solid] or a [rigid] section"
        )
    if s["solid"] is not None and s["rigid"] is not None:
        raise SetupError(
            "rigid",
            "a file has a [solid] or a [rigid] section, not both (both are set by "
            "Params.solid_density); remove one of them",
        )
    return s


def _fluid(table, dim, folder) -> dict:
    t = _Table(table, "fluid")
    f = dict(
        density=t.get("density", "number", positive=True, hint=" (the rest density in kg/m^3)"),
        sound_speed=t.get(
            "sound_speed", "number", positive=True, hint=" (about 10x the largest speed, in m/s)"
        ),
        equation_of_state=t.get("equation_of_state", "string", "tait", choices=("tait", "linear")),
        gamma=t.get("gamma", "number", 7.0, positive=True),
        density_model=t.get(
            "density_model", "string", "continuity", choices=("continuity", "summation")
        ),
        # a term's key given (0 included) chooses the term; absent: no such term
        artificial_viscosity=t.get("artificial_viscosity", "number", None, non_negative=True),
        artificial_beta=t.get("artificial_beta", "number", None, non_negative=True),
        kinematic_viscosity=t.get("kinematic_viscosity", "number", None, non_negative=True),
        density_diffusion=t.get("density_diffusion", "number", None, non_negative=True),
        background_pressure=t.get("background_pressure", "number", 0.0),
        velocity=t.get("velocity", "vector", (0.0,) * dim, length=dim),
        hydrostatic=t.get("hydrostatic", "bool", False),
        transport_velocity=t.get("transport_velocity", "bool", False),
    )
    if "gamma" in t.table and f["equation_of_state"] == "linear":
        raise SetupError("fluid.gamma", "applies to the Tait equation of state only; remove it")
    if f["density_diffusion"] is not None and f["density_model"] != "continuity":
        raise SetupError(
            "fluid.density_diffusion",
            "applies to density_model = 'continuity' only; remove it or change density_model",
        )

    def options(shape_table):
        return dict(velocity=shape_table.get("velocity", "vector", f["velocity"], length=dim))

    f["shapes"] = _shapes(t, "shapes", dim, folder, options)
    t.done()
    return f


def _walls(table, dim, folder) -> dict:
    t = _Table(table, "walls")
    w = dict(
        slip=t.get("slip", "string", "no_slip", choices=("no_slip", "free_slip")),
        layers=t.get("layers", "number", None, positive=True, integer=True),
    )

    def options(shape_table):
        side = shape_table.get("side", "string", "outside", choices=WALL_SIDES)
        layers = shape_table.get("layers", "number", w["layers"], positive=True, integer=True)
        open_top = shape_table.get("open_top", "bool", False)
        if open_top and side != "outside":
            raise SetupError(
                shape_table.key("open_top"), f"applies to side = 'outside' walls, not '{side}'"
            )
        velocity = shape_table.get("velocity", "vector", (0.0,) * dim, length=dim)
        if any(velocity) and w["slip"] != "no_slip":
            raise SetupError(
                shape_table.key("velocity"),
                "acts through the no-slip condition only; remove it or set walls.slip = 'no_slip'",
            )
        return dict(side=side, layers=layers, open_top=open_top, velocity=velocity)

    w["shapes"] = _shapes(t, "shapes", dim, folder, options)
    t.done()
    return w


def _solid(table, dim, folder, coupled: bool) -> dict:
    """``[solid]``; ``coupled``: the file has a fluid too, which the solid's ``slip`` and
    ``substeps`` concern."""
    t = _Table(table, "solid")
    s = dict(
        density=t.get("density", "number", positive=True, hint=" (the density in kg/m^3)"),
        young_modulus=t.get("young_modulus", "number", positive=True, hint=" (E in Pa)"),
        poisson_ratio=t.get("poisson_ratio", "number", hint=" (a number in (-1, 0.5))"),
        penalty_alpha=t.get("penalty_alpha", "number", None, non_negative=True),
        velocity=t.get("velocity", "vector", (0.0,) * dim, length=dim),
        slip=t.get("slip", "string", None, choices=("no_slip", "free_slip")),
        substeps=_substeps(t),
    )
    if not -1.0 < s["poisson_ratio"] < 0.5:
        raise SetupError(
            "solid.poisson_ratio", f"must lie in (-1, 0.5), got {s['poisson_ratio']:g}"
        )
    for key in ("slip", "substeps"):
        if s[key] is not None and not coupled:
            raise SetupError(
                f"solid.{key}",
                "concerns a solid in a fluid only (fluid-structure coupling); remove it "
                "or add a [fluid] section",
            )
    if coupled:
        s["slip"] = s["slip"] or "no_slip"
        s["substeps"] = s["substeps"] or "auto"
    s["shapes"] = _shapes(t, "shapes", dim, folder)
    s["clamps"] = _shapes(t, "clamps", dim, folder, required=False)
    t.done()
    return s


def _rigid(table, dim, folder, coupled: bool) -> dict:
    """``[rigid]``: one rigid body (2D), its shapes joined; ``coupled``: the file has a
    fluid too, which the body's ``slip`` concerns."""
    t = _Table(table, "rigid")
    if dim != 2:
        raise SetupError("rigid", f"rigid bodies are 2D (RigidSystem) but dim = {dim}; use dim = 2")
    r = dict(
        density=t.get("density", "number", positive=True, hint=" (the density in kg/m^3)"),
        velocity=t.get("velocity", "vector", (0.0,) * dim, length=dim),
        slip=t.get("slip", "string", None, choices=("no_slip", "free_slip")),
    )
    if r["slip"] is not None and not coupled:
        raise SetupError(
            "rigid.slip", "concerns a body in a fluid only; remove it or add a [fluid] section"
        )
    r["slip"] = r["slip"] or "no_slip"
    r["shapes"] = _shapes(t, "shapes", dim, folder)
    t.known.append("contact")
    r["contact"] = _wall_contact(t) if "contact" in table else None
    t.done()
    return r


def _wall_contact(rigid: _Table) -> dict:
    """``[rigid.contact]``: the body's contact with the walls: ``wall_contact``
    (:class:`WallContact`, its static distance) and ``values``, its Params fields."""
    t = _Table(rigid.table["contact"], rigid.key("contact"))
    frequency = t.get("frequency", "number", positive=True, hint=" (omega in rad/s)")
    damping_ratio = t.get("damping_ratio", "number", 1.0, non_negative=True)
    distance = t.get("distance", "number", 1.5)
    if not distance >= 1.0:
        raise SetupError(t.key("distance"), f"must be >= 1 (particle spacings), got {distance!r}")
    friction = t.get("friction", "number", 0.5, non_negative=True)
    t.done()
    values = dict(
        contact_frequency=frequency,
        contact_damping_ratio=damping_ratio,
        contact_friction=friction,
    )
    return dict(wall_contact=WallContact(distance=distance), values=values)


def _substeps(t: _Table):
    """``solid.substeps``: a whole number >= 1 or ``"auto"``; ``None`` when absent."""
    t.known.append("substeps")
    value = t.table.get("substeps")
    if value is None or value == "auto":
        return value
    if isinstance(value, str):
        raise SetupError(t.key("substeps"), f'must be a whole number >= 1 or "auto", got {value!r}')
    return _number(t.key("substeps"), value, positive=True, integer=True)


def _domain(table, dim) -> dict:
    t = _Table(table, "domain")
    d = dict(
        lower=t.get("lower", "vector", length=dim),
        upper=t.get("upper", "vector", length=dim),
        periodic=t.get("periodic", "bools", (False,) * dim, length=dim),
    )
    t.done()
    for i, (lo, hi) in enumerate(zip(d["lower"], d["upper"], strict=True)):
        if not hi > lo:
            raise SetupError("domain.upper", f"[{i}] = {hi:g} must exceed lower[{i}] = {lo:g}")
    return d


# ---------------------------------------------------------------------------- building


def _keys(x, dx, origin) -> np.ndarray:
    """Integer lattice indices of sites ``origin + (i + 1/2) dx``."""
    return np.round((x - origin) / dx - 0.5).astype(np.int64)


def _unique_sites(blocks, dx, origin):
    """Concatenate ``[(positions, tag), ...]``, keeping the first of coinciding sites;
    returns ``(positions, tags)``."""
    if not blocks:
        return np.zeros((0, len(origin))), np.zeros(0, int)
    x = np.concatenate([b for b, _ in blocks])
    tags = np.concatenate([np.full(len(b), t) for t, (b, _) in enumerate(blocks)])
    _, first = np.unique(_keys(x, dx, origin), axis=0, return_index=True)
    keep = np.sort(first)
    return x[keep], tags[keep]


def _members(x, keys_of):
    """Whether each site of ``x`` (its lattice keys) is among ``keys_of``."""
    if len(keys_of) == 0 or len(x) == 0:
        return np.zeros(len(x), bool)
    view = np.ascontiguousarray(np.concatenate([keys_of, x])).view(
        np.dtype((np.void, x.dtype.itemsize * x.shape[1]))
    )
    _, inverse, counts = np.unique(view, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    seen = np.zeros(counts.size, bool)
    seen[inverse[: len(keys_of)]] = True
    return seen[inverse[len(keys_of) :]]


def _check_dx(dx) -> float:
    if (
        isinstance(dx, bool)
        or not isinstance(dx, int | float)
        or not (dx > 0 and math.isfinite(dx))
    ):
        raise SetupError("dx", f"must be a positive number, got {dx!r}")
    return float(dx)


def from_toml(path, *, dx: float | None = None, t_end: float | None = None) -> Case:
    """The :class:`~sphjax.Case` that the set-up file ``path`` describes.

    Args:
      path: a TOML file (keys: docs/setups.md).
      dx, t_end: replace the file's particle spacing and end time.
    """
    s = read_setup(path)
    if dx is not None:
        s["dx"] = _check_dx(dx)
    if t_end is not None:
        if not (t_end > 0 and math.isfinite(t_end)):
            raise SetupError("t_end", f"must be a positive number, got {t_end!r}")
        s["t_end"] = float(t_end)
    return build_setup(s)


def build_setup(s: dict) -> Case:
    """The Case of the checked set-up values ``s`` (from :func:`read_setup`)."""
    dim, dx = s["dim"], s["dx"]
    origin = np.asarray(s["origin"], float)
    kernel = kernel_by_name(s["kernel"])
    h = s["h_factor"] * dx
    cutoff = kernel.support * h
    gravity = np.asarray(s["gravity"], float)
    g_norm = float(np.linalg.norm(gravity))
    up = -gravity / g_norm if g_norm > 0 else np.zeros(dim)

    def sample(shape, key):
        try:
            return geometry.fill(shape, dx, origin).position
        except ValueError as err:
            raise SetupError(key, str(err)) from None

    # fluid sites, the first shape listing a site gives its velocity and depth
    fluid_blocks, fluid = [], s["fluid"]
    if fluid is not None:
        for i, (shape, opts) in enumerate(fluid["shapes"]):
            x = sample(shape, f"fluid.shapes[{i}]")
            corners = np.array(
                np.meshgrid(*zip(*shape.bounds, strict=True), indexing="ij")
            ).reshape(dim, -1)
            top = float(np.max(up @ corners))
            fluid_blocks.append((x, (opts["velocity"], top)))
    # walls
    wall_blocks, obstacles = [], []
    if s["walls"] is not None:
        default_layers = s["walls"]["layers"] or geometry.layers_for(cutoff, dx)
        for i, (shape, opts) in enumerate(s["walls"]["shapes"]):
            key = f"walls.shapes[{i}]"
            layers = opts["layers"] or default_layers
            if opts["side"] == "fill":
                x = sample(shape, key)
            else:
                try:
                    x = geometry.wall_layers(
                        shape, dx, layers, opts["side"], opts["open_top"], origin
                    ).position
                except ValueError as err:
                    raise SetupError(key, str(err)) from None
            if opts["side"] != "outside":
                obstacles.append(shape)
            wall_blocks.append((x, opts))
    solid, rigid = s["solid"], s["rigid"]
    if solid is not None:  # a solid in a fluid displaces it
        obstacles += [shape for shape, _ in solid["shapes"] + solid["clamps"]]
    if rigid is not None:  # so does a rigid body
        obstacles += [shape for shape, _ in rigid["shapes"]]
    x_wall, wall_tag = _unique_sites(wall_blocks, dx, origin)
    x_fluid, fluid_tag = _unique_sites(fluid_blocks, dx, origin)
    if len(x_fluid):
        # the fluid is cut out where an obstacle is; it may not reach into a container's wall
        blocked = np.zeros(len(x_fluid), bool)
        for shape in obstacles:
            blocked |= shape.contains(x_fluid)
        outside = [wall_blocks[t][1]["side"] == "outside" for t in wall_tag]
        outside_walls = x_wall[np.array(outside, bool)]
        clash = _members(_keys(x_fluid, dx, origin), _keys(outside_walls, dx, origin))
        if np.any(clash & ~blocked):
            i = int(fluid_tag[np.flatnonzero(clash & ~blocked)[0]])
            raise SetupError(
                f"fluid.shapes[{i}]",
                f"{int(np.sum(clash & ~blocked))} of its particles lie in the walls; keep the "
                "fluid inside the shapes that the walls surround",
            )
        x_fluid, fluid_tag = x_fluid[~blocked], fluid_tag[~blocked]
    if fluid is not None and len(x_fluid) == 0:
        raise SetupError("fluid.shapes", f"hold no particle at dx = {dx:g}; use a smaller dx")

    # solid and clamped sites
    x_solid, x_clamped = np.zeros((0, dim)), np.zeros((0, dim))
    if solid is not None:
        body = [
            (sample(shape, f"solid.shapes[{i}]"), None)
            for i, (shape, _) in enumerate(solid["shapes"])
        ]
        clamps = [
            (sample(shape, f"solid.clamps[{i}]"), None)
            for i, (shape, _) in enumerate(solid["clamps"])
        ]
        x_body, _ = _unique_sites(body, dx, origin)
        x_clamped, _ = _unique_sites(clamps, dx, origin)
        held = _members(_keys(x_body, dx, origin), _keys(x_clamped, dx, origin))
        x_solid = x_body[~held]
        for key, x_part in (("solid.shapes", x_body), ("solid.clamps", x_clamped)):
            in_walls = _members(_keys(x_part, dx, origin), _keys(x_wall, dx, origin))
            if np.any(in_walls):
                raise SetupError(
                    key,
                    f"{int(in_walls.sum())} of their particles lie in the walls (e.g. at "
                    f"{', '.join(f'{v:.4g}' for v in x_part[np.argmax(in_walls)])}); a solid "
                    "and the walls may touch but not overlap: move or shorten one of them",
                )
        if len(x_solid) == 0:
            raise SetupError(
                "solid.shapes",
                f"hold no free particle at dx = {dx:g}; use a smaller dx or smaller clamps",
            )
    # a rigid body's sites: its shapes joined into one body
    x_rigid = np.zeros((0, dim))
    if rigid is not None:
        body = [
            (sample(shape, f"rigid.shapes[{i}]"), None)
            for i, (shape, _) in enumerate(rigid["shapes"])
        ]
        x_rigid, _ = _unique_sites(body, dx, origin)
        in_walls = _members(_keys(x_rigid, dx, origin), _keys(x_wall, dx, origin))
        if np.any(in_walls):
            raise SetupError(
                "rigid.shapes",
                f"{int(in_walls.sum())} of their particles lie in the walls (e.g. at "
                f"{', '.join(f'{v:.4g}' for v in x_rigid[np.argmax(in_walls)])}); a body "
                "and the walls may touch but not overlap: move or shorten one of them",
            )
        if len(x_rigid) == 0:
            raise SetupError("rigid.shapes", f"hold no particle at dx = {dx:g}; use a smaller dx")

    x = np.concatenate([x_fluid, x_wall, x_solid, x_clamped, x_rigid])
    kind = np.concatenate(
        [
            np.full(len(x_fluid), Kind.FLUID),
            np.full(len(x_wall), Kind.WALL),
            np.full(len(x_solid), Kind.SOLID),
            np.full(len(x_clamped), Kind.CLAMPED),
            np.full(len(x_rigid), Kind.RIGID),
        ]
    ).astype(np.int32)
    velocity = np.zeros_like(x)
    depth = np.zeros(len(x))
    if fluid is not None:
        tags = [fluid_blocks[t][1] for t in fluid_tag]
        velocity[: len(x_fluid)] = np.array([v for v, _ in tags]).reshape(-1, dim)
        if fluid["hydrostatic"]:
            tops = np.array([top for _, top in tags])
            depth[: len(x_fluid)] = tops - x_fluid @ up
    if len(x_wall):  # walls stay in place; the velocity is their surface's (no-slip)
        velocity[kind == Kind.WALL] = [wall_blocks[t][1]["velocity"] for t in wall_tag]
    if solid is not None:
        velocity[kind == Kind.SOLID] = solid["velocity"]
    if rigid is not None:
        velocity[kind == Kind.RIGID] = rigid["velocity"]

    # model and parameters
    systems, values = [], {}
    if fluid is not None:
        # every key given acts: it chooses its term, so that case.params.replace and
        # jax.grad reach it (Params a model does not read are refused)
        given = {key for key, value in fluid.items() if value is not None}
        artificial = bool(given & {"artificial_viscosity", "artificial_beta"})
        morris = "kinematic_viscosity" in given
        viscosity = (ArtificialViscosity(),) * artificial + (MorrisViscosity(),) * morris
        diffusion = "density_diffusion" in given
        eos = TaitEOS(gamma=fluid["gamma"]) if fluid["equation_of_state"] == "tait" else LinearEOS()
        systems.append(
            FluidSystem(
                equation_of_state=eos,
                density=ContinuityDensity()
                if fluid["density_model"] == "continuity"
                else SummationDensity(),
                viscosity=viscosity,
                density_diffusion=MolteniColagrossi() if diffusion else None,
                transport_velocity=TransportVelocity() if fluid["transport_velocity"] else None,
            )
        )
        values.update(
            reference_density=fluid["density"],
            sound_speed=fluid["sound_speed"],
            artificial_alpha=fluid["artificial_viscosity"] or 0.0,
            artificial_beta=fluid["artificial_beta"] or 0.0,
            kinematic_viscosity=fluid["kinematic_viscosity"] or 0.0,
            background_pressure=fluid["background_pressure"],
        )
        if diffusion:
            values["density_diffusion"] = fluid["density_diffusion"]
    if len(x_wall):
        systems.append(WallSystem(AdamiBoundary(no_slip=s["walls"]["slip"] == "no_slip")))
    if solid is not None:
        boundary = SolidBoundary(no_slip=solid["slip"] != "free_slip")
        systems.append(
            SolidSystem(
                penalty=None if solid["penalty_alpha"] is None else PenaltyForce(),
                boundary=boundary,
            )
        )
        values.update(
            young_modulus=solid["young_modulus"],
            poisson_ratio=solid["poisson_ratio"],
            solid_density=solid["density"],
            penalty_alpha=solid["penalty_alpha"] or 0.0,
        )
    if rigid is not None:
        boundary = SolidBoundary(no_slip=rigid["slip"] == "no_slip")
        contact = rigid["contact"] or dict(wall_contact=None, values={})
        systems.append(RigidSystem(boundary, wall_contact=contact["wall_contact"]))
        values.update(solid_density=rigid["density"], **contact["values"])
    params = make_params(dim, gravity=tuple(gravity), **values)
    domain = _model_domain(s, x, dx, gravity)
    model = Model(dim=dim, smoothing_length=h, kernel=kernel, domain=domain, systems=tuple(systems))
    volume = dx**dim
    fluid_like = jnp.asarray(kind <= Kind.WALL)
    depth_j = jnp.asarray(depth)
    eos = systems[0].equation_of_state if fluid is not None else None
    bodies = solid is not None or rigid is not None

    def initial_state(p):
        """Densities (hydrostatic through the inverse equation of state) and masses from
        ``p``; the solid's or the rigid body's from ``p.solid_density``."""
        density = jnp.zeros(len(x))
        mass = jnp.zeros(len(x))
        if fluid is not None:
            rho0 = p.reference_density
            pressure = rho0 * jnp.linalg.norm(p.gravity) * depth_j
            rho = eos.density(pressure, p.fluid)
            density = jnp.where(fluid_like, rho, density)
            mass = jnp.where(fluid_like, rho0 * volume, mass)
        if bodies:
            density = jnp.where(fluid_like, density, p.solid_density)
            mass = jnp.where(fluid_like, mass, p.solid_density * volume)
        # fluid and wall particles: V0 = m / rho (make_state's default), bodies: dx^d
        return make_state(x, velocity, density, mass, kind, volume=volume if bodies else None)

    state = initial_state(params)
    cfl = s["cfl"]
    fluid_cfl, solid_cfl = cfl or FLUID_CFL, cfl or SOLID_CFL
    substeps = solid["substeps"] if solid is not None else None
    if substeps is not None:  # a solid in a fluid: split integration
        if substeps == "auto":
            substeps = split_substeps(state, model, params, fluid_cfl, solid_cfl)
        split = model.system(SolidSystem).replace(substeps=substeps)
        model = model.replace(systems=model.systems[:-1] + (split,))
    if s["dt"] is not None:
        try:
            check_time_step(s["dt"], state, model, params)
        except ValueError as err:
            raise SetupError("time.dt", str(err).removeprefix("dt=")) from None
        dt = s["dt"]
    else:
        dt = stable_time_step(state, model, params, fluid_cfl, solid_cfl)
    info = dict(
        dx=dx,
        setup=s["path"],
        n_fluid=len(x_fluid),
        n_wall=len(x_wall),
        n_solid=len(x_solid),
        n_clamped=len(x_clamped),
        n_rigid=len(x_rigid),
        substeps=substeps,
        dt_given=s["dt"] is not None,
        save_every=s["save_every"],
        save_dt=s["save_dt"],
    )
    return Case(
        name=s["name"],
        state=state,
        model=model,
        params=params,
        dt=float(dt),
        t_end=s["t_end"],
        info=info,
        initial_state=initial_state,
    )


def _model_domain(s, x, dx, gravity) -> Domain:
    """The ``[domain]`` of the file, checked to hold every particle.  By default the box of
    the particles' cells padded by 2 dx: with a fluid, also against gravity by the box's
    height (room for splashes); a solid alone, by the box's largest side on every side."""
    if s["domain"] is not None:
        d = s["domain"]
        lower, upper = np.array(d["lower"]), np.array(d["upper"])
        outside = np.any((x < lower) | (x >= upper), axis=-1)
        if np.any(outside):
            i = int(np.flatnonzero(outside)[0])
            raise SetupError(
                "domain",
                f"{int(outside.sum())} particles lie outside it (e.g. at "
                f"{', '.join(f'{v:.4g}' for v in x[i])}); enlarge domain.lower/upper to "
                f"[{', '.join(f'{v:.4g}' for v in x.min(0) - dx)}] / "
                f"[{', '.join(f'{v:.4g}' for v in x.max(0) + dx)}] at least",
            )
        return Domain(tuple(d["lower"]), tuple(d["upper"]), tuple(d["periodic"]))
    lower = x.min(axis=0) - 0.5 * dx - 2 * dx
    upper = x.max(axis=0) + 0.5 * dx + 2 * dx
    if s["fluid"] is None:  # a body bends, swings or falls: room of its own size all round
        reach = float(np.max(upper - lower))
        lower, upper = lower - reach, upper + reach
    elif np.any(gravity):
        axis = int(np.argmax(np.abs(gravity)))
        height = upper[axis] - lower[axis]
        if gravity[axis] < 0:
            upper[axis] += height
        else:
            lower[axis] -= height
    return Domain(tuple(map(float, lower)), tuple(map(float, upper)), (False,) * len(lower))
