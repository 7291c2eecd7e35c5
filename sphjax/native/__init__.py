"""Pair sums as compiled loops on the CPU (``Model.pair_loop="native"``).

XLA evaluates a pair sum over a neighbour list ``[N, K]`` from both sides: every pair
``(a, b)`` once in ``a``'s row and once in ``b``'s.  A sum within one system whose term
is symmetric or antisymmetric (``parity`` of :func:`sphjax.physics.pairs.pair_sum`) needs
each pair once, its term added to both particles, which XLA cannot express cheaply on the
CPU (the second half is a scatter-add, run serially).  ``pair_sums.cc`` here does it in
C++ loops over the same neighbour list, rows shared between threads, called from the
compiled step as XLA foreign functions (``jax.ffi``):

* ``kernel_sum``: ``sum_b m_b W_ab`` (eq. 5 without the self term);
* ``velocity_divergence``: ``sum_b m_b (v_a - v_b) . grad_a W_ab`` (eq. 11);
* ``continuity_molteni``: eq. 11 with Molteni & Colagrossi's density diffusion;
* ``momentum``: eq. 10's pressure term with Monaghan's ``Pi_ab`` and Morris' viscosity;
* ``extrapolation``: Adami et al.'s sums onto wall particles from the fluid.

The kernel sum, the velocity divergence and the momentum also run between two systems
(a fluid's rows against its walls' columns, over the walls' compacted lists): each pair
from the row's side, rows shared between threads, which spares XLA's gathers of the
neighbours' fields and its per-pair temporaries.

``solid_sums.cc`` has the two pair sums of an elastic solid (total-Lagrangian SPH) over
its reference neighbours, row by row over weights per slot computed once per run from the
stored reference kernel gradients:

* ``deformation_by_rows``: the deformation gradient ``F`` (eq. 16);
* ``elastic_by_rows``: eq. 14's elastic pair forces;

and, each pair once with the pair geometry recomputed from the reference positions,
``solid_momentum``: eq. 14 with Ganzenmüller's penalty force, which a run uses with it.

``cell_list.cc`` rebuilds the neighbour search's list (:func:`cell_list_rebuild`, used by
:class:`sphjax.neighbors.NeighborSearch` when ``SearchGeometry.native``): a counting sort
into cells at least as wide as the search radius and a scan of the cells around each
particle, the rows shared between threads; it writes jax-md's dense list, row by row.

The library is built with the machine's C++ compiler (``$CXX``, else ``g++``, else
``c++``) the first time a run needs it and kept in ``$SPHJAX_NATIVE_DIR`` (default
``~/.cache/sphjax/native``) under a name that changes with the source, the compiler,
jaxlib and the CPU.
Derivatives never go through it: :func:`sphjax.physics.pairs.pair_sum` gives the native
sum XLA's sum as its derivative rule (``jax.custom_jvp``), so ``jax.grad``, ``jax.jvp``
and the pair sums' custom adjoint see exactly the XLA path; the cell list takes its
positions through ``jax.lax.stop_gradient`` (its results are integers).
"""

from __future__ import annotations

import contextlib
import ctypes
import fcntl
import functools
import hashlib
import os
import platform
import shutil
import subprocess
from pathlib import Path

import jax
import numpy as np

from sphjax.core.kernels import KERNELS

#: the library's sources: the pair sums (a fluid's, a solid's) and the neighbour search's
#: cell list
SOURCES = tuple(
    Path(__file__).with_name(name) for name in ("pair_sums.cc", "solid_sums.cc", "cell_list.cc")
)
#: the headers they include (part of the build's key)
HEADERS = tuple(
    Path(__file__).with_name(name)
    for name in ("threads.h", "pair_geometry.h", "cell_blocked.h", "pair_loop.h")
)
FLAGS = (
    "-O3",
    "-march=native",
    "-fno-math-errno",  # sqrt without errno: the pair loops vectorise
    "-fno-trapping-math",
    "-fopenmp-simd",
    "-std=c++17",
    "-shared",
    "-fPIC",
    "-pthread",
)
#: the handlers of ``pair_sums.cc``, ``solid_sums.cc`` and ``cell_list.cc``: XLA target name
#: -> exported symbol
TARGETS = {
    "sphjax_kernel_sum": "SphjaxKernelSum",
    "sphjax_velocity_divergence": "SphjaxVelocityDivergence",
    "sphjax_continuity_molteni": "SphjaxContinuityMolteni",
    "sphjax_momentum": "SphjaxMomentum",
    "sphjax_extrapolation": "SphjaxExtrapolation",
    "sphjax_solid_momentum": "SphjaxSolidMomentum",
    "sphjax_deformation_by_rows": "SphjaxDeformationByRows",
    "sphjax_elastic_by_rows": "SphjaxElasticByRows",
    "sphjax_cell_list_rebuild": "SphjaxCellListRebuild",
}
#: the kernels ``pair_sums.cc`` knows, by name (its ids)
KERNEL_IDS = {"cubic_spline": 0, "quintic_spline": 1, "wendland_c2": 2, "wendland_c4": 3}


class NativeUnavailable(RuntimeError):
    """``Model.pair_loop="native"`` cannot run here (no compiler, not a CPU)."""


def compiler() -> str | None:
    """The C++ compiler to build with: ``$CXX``, else ``g++``, else ``c++`` (``None``)."""
    for name in (os.environ.get("CXX"), "g++", "c++"):
        if name and shutil.which(name):
            return name
    return None


def _cache_dir() -> Path:
    """Where built libraries are kept: ``$SPHJAX_NATIVE_DIR``, else
    ``$XDG_CACHE_HOME/sphjax/native`` (default ``~/.cache/sphjax/native``); apart from the
    compiled-program cache of ``SPHJAX_CACHE_DIR``, which may be off: the loops are
    needed to run."""
    if os.environ.get("SPHJAX_NATIVE_DIR"):
        return Path(os.environ["SPHJAX_NATIVE_DIR"])
    root = os.environ.get("XDG_CACHE_HOME") or os.path.expanduser("~/.cache")
    return Path(root) / "sphjax" / "native"


def _cpu_model() -> str:
    with contextlib.suppress(OSError):
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line
    return platform.processor()


@functools.cache
def library() -> str:
    """Path of the built library (built now if no build of this source is cached)."""
    cxx = compiler()
    if cxx is None:
        raise NativeUnavailable(
            "Model.pair_loop='native' needs a C++ compiler to build sphjax's pair loops "
            "and none was found ($CXX, g++, c++); install one or use pair_loop='xla'"
        )
    version = subprocess.run([cxx, "--version"], capture_output=True, text=True).stdout
    key = hashlib.sha256(
        "\n".join(
            [
                *(source.read_text() for source in SOURCES + HEADERS),
                " ".join(FLAGS),
                version,
                jax.__version__,
                _cpu_model(),
            ]
        ).encode()
    ).hexdigest()[:16]
    directory = _cache_dir()
    directory.mkdir(parents=True, exist_ok=True)
    target = directory / f"pair_sums-{key}.so"
    with open(directory / "build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one build at a time (test workers, processes)
        if not target.exists():
            partial = target.with_suffix(f".{os.getpid()}.tmp")
            _build(cxx, partial)
            os.replace(partial, target)
    return str(target)


def _build(cxx: str, target: Path) -> None:
    """Compile the sources side by side (one compiler process each: the machine's cores
    share the work), then link them into ``target``."""
    include = ["-I", jax.ffi.include_dir()]
    objects = [target.with_suffix(f".{source.stem}.o") for source in SOURCES]
    compiles = [
        subprocess.Popen(
            [cxx, *FLAGS, *include, "-c", str(source), "-o", str(obj)],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        for source, obj in zip(SOURCES, objects, strict=True)
    ]
    errors = [process.communicate()[1] for process in compiles]
    failures = [e for process, e in zip(compiles, errors, strict=True) if process.returncode]
    if not failures:
        linked = subprocess.run(
            [cxx, *FLAGS, "-o", str(target), *map(str, objects)], capture_output=True, text=True
        )
        failures = [linked.stderr] if linked.returncode != 0 else []
    for obj in objects:
        obj.unlink(missing_ok=True)
    if failures:
        last = (failures[0].strip().splitlines() or ["no message"])[-1]
        raise NativeUnavailable(
            f"Model.pair_loop='native': {cxx} could not build sphjax's pair loops "
            f"({last}); use pair_loop='xla'"
        )


@functools.cache
def register() -> None:
    """Build (if needed) and register the handlers with XLA's CPU backend, once."""
    if jax.default_backend() != "cpu":
        raise NativeUnavailable(
            "Model.pair_loop='native' runs on the CPU only; JAX's default device here is "
            f"{jax.default_backend()!r}: use pair_loop='xla'"
        )
    handle = ctypes.cdll.LoadLibrary(library())
    for target, symbol in TARGETS.items():
        capsule = jax.ffi.pycapsule(getattr(handle, symbol))
        jax.ffi.register_ffi_target(target, capsule, platform="cpu")


def supports(geometry) -> bool:
    """Whether ``pair_sums.cc`` has ``geometry``'s kernel (the four of
    :data:`sphjax.core.kernels.KERNELS`, not a subclass a user wrote)."""
    return type(geometry.kernel) in KERNELS.values()


def _kernel_name(kernel) -> str:
    return next(name for name, cls in KERNELS.items() if type(kernel) is cls)


def _attributes(geometry) -> dict:
    """The pair geometry as the handlers' attributes (kernel, ``h``, cutoff, box)."""
    size = list(geometry.domain.size) + [1.0] * (3 - geometry.dim)
    periodic = sum(1 << i for i, p in enumerate(geometry.domain.periodic) if p)
    return dict(
        kernel=np.int64(KERNEL_IDS[_kernel_name(geometry.kernel)]),
        h=np.float64(geometry.smoothing_length),
        cutoff=np.float64(geometry.cutoff),
        sigma=np.float64(geometry.kernel.normalisation(geometry.dim)),
        lx=np.float64(size[0]),
        ly=np.float64(size[1]),
        lz=np.float64(size[2]),
        periodic=np.int64(periodic),
    )


def _call(target, shape, dtype, geometry, *args, cross: bool = False, **attributes):
    register()
    result = jax.ShapeDtypeStruct(shape, dtype)
    call = jax.ffi.ffi_call(target, result, vmap_method="sequential")
    return call(*args, **_attributes(geometry), cross=bool(cross), **attributes)


def _list(idx):
    return idx.astype(np.int32)


def _sides(rows: dict, columns: dict | None, keys: str):
    """The fields ``keys`` of the rows, then of the columns (the rows again within one
    system), and whether the sum is between two systems."""
    other = rows if columns is None else columns
    fields = keys.split()
    return [rows[k] for k in fields] + [other[k] for k in fields], columns is not None


def kernel_sum(rows, idx, geometry, columns=None):
    """``sum_b m_b W_ab`` (``[N]``; no self term) over ``idx``: within one system
    (``columns=None``; the list symmetric, each pair once) or the rows against the
    ``columns`` of another (fields ``x``, ``m``)."""
    fields, cross = _sides(rows, columns, "x m")
    m = rows["m"]
    return _call("sphjax_kernel_sum", m.shape, m.dtype, geometry, *fields, _list(idx), cross=cross)


def velocity_divergence(rows, idx, geometry, columns=None):
    """``sum_b m_b (v_a - v_b) . grad_a W_ab`` (``[N]``, eq. 11) over ``idx``, within one
    system or against ``columns`` (fields ``x``, ``v``, ``m``; see :func:`kernel_sum`)."""
    fields, cross = _sides(rows, columns, "x v m")
    m = rows["m"]
    return _call(
        "sphjax_velocity_divergence", m.shape, m.dtype, geometry, *fields, _list(idx), cross=cross
    )


def continuity_molteni(rows, idx, geometry, parameters):
    """Eq. 11 with Molteni & Colagrossi's density diffusion, its hydrostatic part removed
    (:func:`sphjax.physics.fluid.density_diffusion.molteni_term`), over the symmetric list
    ``idx`` of one fluid (``[N]``; fields ``x, v, m, rho``).  ``parameters``: ``(gravity
    [d], reference_density, sound_speed, density_diffusion)``."""
    x = rows["x"]
    gravity, *scalars = (jax.numpy.asarray(q, x.dtype) for q in parameters)
    fields = [rows[k] for k in ("x", "v", "m", "rho")]
    return _call(
        "sphjax_continuity_molteni",
        rows["m"].shape,
        x.dtype,
        geometry,
        *fields,
        _list(idx),
        gravity,
        *scalars,
    )


def momentum(rows, idx, geometry, parameters, *, artificial: bool, morris: bool, columns=None):
    """Eq. 10's pair terms per unit of the rows' own mass, ``[N, d]``:
    ``sum_b m_b [-(p_a/rho_a^2 + p_b/rho_b^2 + Pi_ab) grad_a W_ab + Morris]``, within one
    system or against ``columns`` (fields ``x, v, m, rho, p``; see :func:`kernel_sum`;
    ``v`` of the columns is the velocity the viscous terms see).

    ``parameters``: ``(sound_speed, artificial_alpha, artificial_beta,
    kinematic_viscosity)`` (arrays of the run's dtype); ``artificial``, ``morris``: which
    viscous terms (Monaghan's ``Pi_ab``, Morris et al. 1997)."""
    x = rows["x"]
    scalars = [jax.numpy.asarray(q, x.dtype) for q in parameters]
    fields, cross = _sides(rows, columns, "x v m rho p")
    return _call(
        "sphjax_momentum",
        x.shape,
        x.dtype,
        geometry,
        *fields,
        _list(idx),
        *scalars,
        cross=cross,
        artificial=bool(artificial),
        morris=bool(morris),
    )


def extrapolation(rows, idx, geometry, columns):
    """Adami et al.'s sums onto boundary particles (the rows, field ``x``) from their fluid
    neighbours (``columns``: ``x, p, rho, v``): ``[N, 2 + 2 d]`` holding ``sum_b W_ab``,
    ``sum_b p_b W_ab``, ``sum_b rho_b W_ab r_ab`` and ``sum_b W_ab v_b``
    (:func:`sphjax.physics.boundary.wall.extrapolation_terms`)."""
    x = rows["x"]
    n, dim = x.shape
    fields = [x] + [columns[k] for k in ("x", "p", "rho", "v")]
    return _call(
        "sphjax_extrapolation",
        (n, 2 + 2 * dim),
        x.dtype,
        geometry,
        *fields,
        _list(idx),
        cross=True,
    )


def solid_momentum(X, x, V, PL0, F, idx, geometry, parameters, *, penalty: bool):
    """Eq. 14's pair terms per unit of the rows' own mass, ``[N, d]``:
    ``sum_b V0_b [(P L0)_a + (P L0)_b] grad0_a W(X_ab) / rho0`` plus, with ``penalty``,
    Ganzenmüller's (2015) hourglass force ``f^PF_a / m0_a``
    (:func:`sphjax.physics.solid.penalty.penalty_force`), over the symmetric reference list
    ``idx``.

    Args:
      X, x: ``[N, d]`` reference and current positions.
      V: ``[N]`` reference volumes.
      PL0: ``[N, d, d]`` ``P_a L0_a``, the first Piola-Kirchhoff stress times eq. 15's
        correction.
      F: ``[N, d, d]`` deformation gradients (read by the penalty force only).
      parameters: ``(solid_density, young_modulus, penalty_alpha)``.
    """
    scalars = [jax.numpy.asarray(q, X.dtype) for q in parameters]
    return _call(
        "sphjax_solid_momentum",
        X.shape,
        X.dtype,
        geometry,
        X,
        x,
        V,
        PL0,
        F,
        _list(idx),
        *scalars,
        penalty=bool(penalty),
    )


def _box(domain, dim: int) -> dict:
    """The box as the stored-weight loops' attributes (lengths, periodic axes as bits)."""
    size = list(domain.size) + [1.0] * (3 - dim)
    periodic = sum(1 << i for i, p in enumerate(domain.periodic) if p)
    return dict(
        lx=np.float64(size[0]),
        ly=np.float64(size[1]),
        lz=np.float64(size[2]),
        periodic=np.int64(periodic),
    )


def _neighbour_volumes(V, idx):
    """``V0_b`` per slot of ``idx`` (``[N, K]``; 0 in the free slots)."""
    n = V.shape[0]
    return jax.numpy.where(idx < n, V[jax.numpy.minimum(idx, n - 1)], 0.0)


def deformation_by_rows(x, V, L0, grad_w, idx, domain):
    """The deformation gradient ``F_a = -sum_b V0_b x_ab (L0_a grad0_a W(X_ab))^T``
    (eq. 16), ``[N, d, d]``, row by row over the reference list ``idx``.

    The weights per slot ``c_ab = V0_b L0_a grad0_a W(X_ab)`` depend on the reference
    configuration only: inside a run's loop of steps XLA computes them once, before it.

    Args:
      x: ``[N, d]`` current positions (``x_ab``, minimum image on ``domain``'s periodic
        axes).
      V: ``[N]`` reference volumes ``V0``.
      L0: ``[N, d, d]`` the correction matrices (eq. 15).
      grad_w: ``[N, K, d]`` ``grad0_a W(X_ab)`` per slot of ``idx`` (0 in free slots).
      idx: ``[N, K]`` the reference list (free slots hold ``N`` or more).
      domain: the box (:class:`sphjax.core.space.Domain`).
    """
    register()
    n, d = x.shape
    weights = _neighbour_volumes(V, idx)[..., None] * jax.numpy.einsum("aij,akj->aki", L0, grad_w)
    call = jax.ffi.ffi_call(
        "sphjax_deformation_by_rows",
        jax.ShapeDtypeStruct((n, d, d), x.dtype),
        vmap_method="sequential",
    )
    return call(x, weights.astype(x.dtype), _list(idx), **_box(domain, d))


def elastic_by_rows(V, PL0, grad_w, idx, solid_density):
    """Eq. 14's elastic pair terms per unit of the rows' own mass, ``[N, d]``:
    ``sum_b V0_b [(P L0)_a + (P L0)_b] grad0_a W(X_ab) / rho0``, row by row over the
    reference list ``idx``; ``PL0``: ``[N, d, d]`` ``P_a L0_a``; ``grad_w``: ``[N, K, d]``
    ``grad0_a W(X_ab)`` per slot.  The weights per slot ``V0_b grad0_a W(X_ab)`` depend
    on the reference configuration only (computed once before a run's loop of steps)."""
    register()
    weights = _neighbour_volumes(V, idx)[..., None] * grad_w
    call = jax.ffi.ffi_call(
        "sphjax_elastic_by_rows",
        jax.ShapeDtypeStruct(grad_w.shape[:1] + grad_w.shape[2:], grad_w.dtype),
        vmap_method="sequential",
    )
    rho0 = jax.numpy.asarray(solid_density, grad_w.dtype)
    return call(PL0, weights.astype(grad_w.dtype), _list(idx), rho0)


def cell_list_rebuild(x, width: int, *, box, cell_size, cells, radius2: float, capacity=None):
    """A dense neighbour list of the positions ``x`` (``[N, d]``, in the search's box
    ``[0, L)`` per axis), built by ``cell_list.cc``'s counting sort into a grid of cells.

    Args:
      x: ``[N, d]`` positions (float32 or float64; no derivative: integer results).
      width: ``K``, the slots per row of the list.
      box: ``[d]`` the box's lengths ``L`` (every axis wraps: the minimum image).
      cell_size: ``[d]`` the grid's spacing, at least the search radius.
      cells: ``[d]`` cells per axis (an axis of fewer than 3 is searched as one cell).
      radius2: the squared search radius (compared in the positions' precision).
      capacity: the slots per cell of the jax-md cell list whose order the rows follow
        (``None``: within a cell, increasing index).
    Returns:
      ``(idx, sizes)``: ``[N, K]`` int32 neighbours within the radius (self left out,
      the first ``K`` of each row, padded with ``N``) and ``[2]`` int32: the most
      neighbours of one particle and the most particles in one cell.
    """
    register()
    n, dim = x.shape
    pad = [1.0] * (3 - dim)
    box, cell_size = list(map(float, box)) + pad, list(map(float, cell_size)) + pad
    cells = [int(c) for c in cells] + [1] * (3 - dim)
    results = (
        jax.ShapeDtypeStruct((n, width), np.int32),
        jax.ShapeDtypeStruct((2,), np.int32),
    )
    call = jax.ffi.ffi_call("sphjax_cell_list_rebuild", results, vmap_method="sequential")
    return call(
        jax.lax.stop_gradient(x),
        lx=np.float64(box[0]),
        ly=np.float64(box[1]),
        lz=np.float64(box[2]),
        cx=np.float64(cell_size[0]),
        cy=np.float64(cell_size[1]),
        cz=np.float64(cell_size[2]),
        nx=np.int64(cells[0]),
        ny=np.int64(cells[1]),
        nz=np.int64(cells[2]),
        radius2=np.float64(radius2),
        capacity=np.int64(capacity or 0),
    )
