"""``sphjax run``: build the case from the command line, plan the saving, run, report.

Imported by :mod:`sphjax.cli` only when a command needs the solver (this imports JAX).
"""

from __future__ import annotations

import dataclasses
import difflib
import inspect
import math
import re
import sys
import time
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from sphjax import cases
from sphjax._text import show
from sphjax.cli import CHUNK_STEPS, DEFAULT_FRAMES, EXIT_OK, EXIT_UNSTABLE, UsageError
from sphjax.integration.timestep import check_time_step, stable_time_step

# ---------------------------------------------------------------------------- the case


_KINDS = {
    "bool": "True or False",
    "int": "a whole number",
    "float": "a number",
    "str": "a name",
    "None": "None",
}


def _accepted_kinds(parameter) -> list[str]:
    """The types a case argument takes, from its annotation (or else its default)."""
    annotation = parameter.annotation
    if isinstance(annotation, str):  # ``from __future__ import annotations``
        kinds = [k.strip() for k in annotation.split("|")]
        if all(k in _KINDS for k in kinds):
            return kinds
    default = parameter.default
    if default is None:
        return []  # anything: the case checks it
    return [type(default).__name__] if type(default).__name__ in _KINDS else []


def _check_case_value(name: str, key: str, value, parameter):
    """A --case-arg value of a type the case argument takes (numbers, flags, names)."""
    kinds = _accepted_kinds(parameter)
    if not kinds:
        return value
    if value is None and "None" in kinds:
        return value
    if isinstance(value, bool):
        if "bool" in kinds:
            return value
    elif isinstance(value, int | float) and ("int" in kinds or "float" in kinds):
        if not math.isfinite(value):
            raise UsageError(
                f"--case-arg {key}", f"{key}={show(value)}: case {name!r} expects a finite number"
            )
        if "float" not in kinds and isinstance(value, float) and value.is_integer():
            value = int(value)
        return value
    elif isinstance(value, str) and "str" in kinds:
        return value
    if kinds == ["str"] and not isinstance(value, bool):  # a name that parsed as a literal
        return str(value)
    what = " or ".join(_KINDS[k] for k in kinds)
    raise UsageError(
        "--case-arg",
        f"{key}={show(value)}: case {name!r} expects {what} (default {show(parameter.default)})",
    )


def build_case(name: str, case_args: dict, *, n=None, dx=None, t_end=None):
    """The case ``name`` with ``--case-arg`` values and ``--n``/``--dx``/``--t-end``."""
    if name not in cases.CASES:
        close = difflib.get_close_matches(name, cases.CASES, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise UsageError(
            "CASE", f"unknown case {name!r}{hint}; available cases: {', '.join(cases.CASES)}"
        )
    accepted = inspect.signature(cases.CASES[name]).parameters
    kwargs = {}
    for key, value in case_args.items():
        if key not in accepted:
            raise UsageError(
                "--case-arg",
                f"case {name!r} has no argument {key!r}; it accepts {', '.join(accepted)}",
            )
        given = {"n": "--dx" if dx is not None else "--n" if n is not None else None,
                 "t_end": "--t-end" if t_end is not None else None}.get(key)  # fmt: skip
        if given:
            raise UsageError("--case-arg", f"{key} is also given by {given}; give it once")
        kwargs[key] = _check_case_value(name, key, value, accepted[key])
    if n is not None:
        kwargs["n"] = n
    if t_end is not None and "t_end" in accepted:
        kwargs["t_end"] = t_end
    try:
        case = cases.get(name, dx=dx, **kwargs)
    except (ValueError, TypeError) as err:
        message = str(err)
        named = [k for k in case_args if re.search(rf"(?<![\w-]){re.escape(k)}(?![\w-])", message)]
        argument = (
            f"--case-arg {named[0]}" if len(named) == 1
            else "--case-arg" if named
            else "--dx" if dx is not None
            else "--n" if n is not None
            else "--case-arg" if case_args
            else "CASE"
        )  # fmt: skip
        raise UsageError(argument, message) from None
    if t_end is not None and "t_end" not in accepted:
        case = case.replace(t_end=t_end)
    return case


def is_setup_file(name: str) -> bool:
    """Whether ``sphjax run NAME`` names a set-up file rather than a case."""
    return name.lower().endswith(".toml")


def build_setup_case(args):
    """The case of ``sphjax run FILE.toml`` with ``--dx`` and ``--t-end``."""
    from sphjax.cases.setup_file import SetupError, from_toml

    for flag, given in (("--n", args.n), ("--case-arg", args.case_arg)):
        if given:
            fix = "set dx in the file or pass --dx" if flag == "--n" else "edit the file"
            raise UsageError(flag, f"applies to the named cases; for a set-up file {fix}")
    if not Path(args.case).is_file():
        raise UsageError(
            "CASE",
            f"'{args.case}' does not exist; give the path of a set-up file FILE.toml, or a "
            "case name (see `sphjax cases`)",
        )
    try:
        return from_toml(args.case, dx=args.dx, t_end=args.t_end)
    except SetupError as err:
        if err.key in ("dx", "t_end") and getattr(args, err.key) is not None:  # from here
            argument = "--dx" if err.key == "dx" else "--t-end"
            raise UsageError(argument, str(err).removeprefix(f"{err.key}: ")) from None
        raise UsageError(args.case, str(err)) from None


def apply_sets(case, sets: list[tuple[str, float | tuple]]):
    """``case`` with ``--set FIELD=VALUE`` applied to its Params.

    A field the case's model does not read is refused, naming the choice that would read
    it (:class:`~sphjax.UnusedParameterError`).  The case's time step is shortened in
    proportion when the new values lower the stable step (a larger sound speed or Young's
    modulus), so the case's Courant number is kept.
    """
    if not sets:
        return case
    changes = {}
    fields = [name for name, _ in case.params.items()]
    used = [name for name, _ in case.params.items(used_only=True)]
    for name, value in sets:
        if name not in fields:
            raise UsageError(
                "--set",
                f"{name!r} is not a parameter of this case; choose one of {', '.join(used)}",
            )
        try:
            case.params.check_used(name)
        except ValueError as err:
            raise UsageError("--set", str(err)) from None
        old = np.asarray(getattr(case.params, name))
        new = np.asarray(value, dtype=float)
        if new.shape != old.shape:
            example = ",".join(f"{v:g}" for v in old.ravel()) if old.ndim else f"{float(old):g}"
            count = "a number" if old.ndim == 0 else f"{old.size} comma-separated numbers"
            raise UsageError(
                "--set", f"{name} takes {count} (now {name}={example}), got {name}={value}"
            )
        changes[name] = jnp.asarray(new, old.dtype)
    try:
        params = case.params.replace(**changes)
    except (ValueError, TypeError) as err:
        raise UsageError("--set", str(err)) from None
    before = stable_time_step(case.state, case.model, case.params)
    after = stable_time_step(case.state, case.model, params)
    dt = case.dt * min(1.0, after / before) if before > 0 and math.isfinite(after) else case.dt
    return case.replace(params=params, dt=dt)


# ---------------------------------------------------------------------------- saving


def with_neighbor_margin(case, margin: float):
    """``case`` with ``Model.neighbor_margin``."""
    try:
        return case.replace(model=case.model.replace(neighbor_margin=margin))
    except ValueError as err:
        raise UsageError("--neighbor-margin", str(err)) from None


def with_pair_loop(case, pair_loop: str):
    """``case`` with ``Model.pair_loop``; for ``"native"`` the loops are built (or found
    built) now, so that a machine without a compiler is told before the run starts."""
    import dataclasses

    from sphjax import native

    try:
        case = case.replace(model=dataclasses.replace(case.model, pair_loop=pair_loop))
        if pair_loop == "native":
            native.register()
    except (ValueError, native.NativeUnavailable) as err:
        raise UsageError("--pair-loop", str(err)) from None
    return case


def _divisors(n: int) -> list[int]:
    small = [d for d in range(1, math.isqrt(n) + 1) if n % d == 0]
    return sorted(set(small + [n // d for d in small]))


def default_save_every(n_steps: int) -> int:
    """About DEFAULT_FRAMES frames: a divisor of ``n_steps`` giving 50-100 frames if
    there is one (every frame the same interval), else ``ceil(n_steps / 100)``."""
    if n_steps <= DEFAULT_FRAMES:
        return 1
    for d in _divisors(n_steps):
        if DEFAULT_FRAMES // 2 <= n_steps // d <= DEFAULT_FRAMES:
            return d
    return math.ceil(n_steps / DEFAULT_FRAMES)


def frames_per_chunk(n_frames: int, save_every: int) -> int:
    """A divisor of ``n_frames`` so every chunk has the same length (one compilation)."""
    fitting = [d for d in _divisors(max(n_frames, 1)) if d * save_every <= CHUNK_STEPS]
    return max(fitting) if fitting else 1


@dataclasses.dataclass
class Plan:
    dt: float
    n_steps: int
    save_every: int
    note: str = ""

    @property
    def n_frames(self) -> int:
        """Saved frames, the initial one and a last one at the end time included."""
        full, rest = divmod(self.n_steps, self.save_every)
        return 1 + full + (rest > 0)


def plan(case, *, dt=None, t_end=None, save_every=None, save_dt=None) -> Plan:
    """Time step, number of steps and save interval, checked before anything runs."""
    note = ""
    given_t_end = t_end is not None
    if dt is not None:
        try:
            check_time_step(dt, case.state, case.model, case.params)
        except ValueError as err:
            raise UsageError("--dt", str(err)) from None
    step = case.dt if dt is None else dt
    if save_dt is not None:
        ratio = save_dt / step
        if dt is not None:
            if ratio < 1 - 1e-9 or abs(ratio - round(ratio)) > 1e-6 * ratio:
                lo = max(1, math.floor(ratio)) * dt
                raise UsageError(
                    "--save-dt",
                    f"{save_dt:g} is not a whole number of --dt {dt:g} steps; use e.g. "
                    f"--save-dt {lo:g} or {lo + dt:g}, or leave out --dt",
                )
        else:
            k = max(1, math.ceil(ratio - 1e-9))
            if step != save_dt / k:
                note = f" (shortened from {step:.4g} so frames fall every {save_dt:g})"
            step = save_dt / k
        save_every = max(1, round(save_dt / step))
    t_end = case.t_end if t_end is None else t_end
    if save_dt is not None and save_dt > t_end * (1 + 1e-9):
        whose = "--t-end" if given_t_end else "the case's end time"
        raise UsageError(
            "--save-dt",
            f"{save_dt:g} s is longer than the run ({whose} {t_end:g} s), so no frame would "
            f"fall inside it; use e.g. --save-dt {t_end / 10:.3g}, or a longer --t-end",
        )
    n_steps = max(1, math.ceil(t_end / step - 1e-9))  # the rule of sphjax.simulate
    if save_every is None:
        save_every = default_save_every(n_steps)
    return Plan(step, n_steps, save_every, note)


# ---------------------------------------------------------------------------- run


#: a run whose estimated wall time exceeds this says so before it goes on
LONG_RUN_SECONDS = 600.0


def _duration(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    return f"{seconds / 3600:.1f} h"


def _candidates(args, base) -> str:
    """What the command changed from the case's defaults, as causes of an instability."""
    changed = []
    for name, value in args.set:
        old = np.asarray(getattr(base.params, name))
        was = ",".join(f"{v:g}" for v in old.ravel()) if old.ndim else f"{float(old):g}"
        now = ",".join(f"{v:g}" for v in value) if isinstance(value, tuple) else f"{value:g}"
        changed.append(f"--set {name}={now} (the case's value: {was})")
    changed += [f"--case-arg {key}={show(value)}" for key, value in args.case_arg]
    if args.dt is not None:
        changed.append(f"--dt {args.dt:g} (the case's stable step: {base.dt:.4g})")
    if not changed:
        return "Try a smaller --dt."
    return (
        "Changed from the case's defaults, and candidates for the cause: "
        + "; ".join(changed)
        + ". Undo them one at a time, or try a smaller --dt."
    )


def _one_line_warnings(bar):
    """Show a neighbour-list re-allocation as one line above the progress bar."""
    import warnings

    from sphjax.neighbors import NeighborOverflowWarning

    show_default = warnings.showwarning

    def show_warning(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, NeighborOverflowWarning):
            bar.write(f"note: {message} (one more compilation)", file=sys.stderr)
        else:
            show_default(message, category, filename, lineno, file, line)

    return show_warning


def run_case(args, out: Path) -> int:
    import warnings

    import jax
    from tqdm import tqdm

    from sphjax._compile import CompileTimer, remember_rate, remembered_rate
    from sphjax.integration.simulate import SimulationError, simulate
    from sphjax.io import TrajectoryWriter
    from sphjax.neighbors import is_neighbor_overflow

    dt, save_every, save_dt = args.dt, args.save_every, args.save_dt
    if is_setup_file(args.case):
        case = build_setup_case(args)
        if save_every is None and save_dt is None:  # the file's saving, unless given here
            save_every, save_dt = case.info["save_every"], case.info["save_dt"]
        # the file's time.dt (checked when the case was built) is the case's step: like a
        # case's own step it is shortened to fit save_dt or a stiffer --set, never lengthened
    else:
        case = build_case(args.case, dict(args.case_arg), n=args.n, dx=args.dx, t_end=args.t_end)
    base = case
    case = apply_sets(case, args.set)
    if args.pair_loop != case.model.pair_loop:
        case = with_pair_loop(case, args.pair_loop)
    if args.neighbor_margin is not None:
        case = with_neighbor_margin(case, args.neighbor_margin)
    p = plan(case, dt=dt, t_end=args.t_end, save_every=save_every, save_dt=save_dt)
    full = p.n_steps // p.save_every
    chunk = frames_per_chunk(full, p.save_every) * p.save_every
    dx = case.info.get("dx", float("nan"))
    print(
        f"{case.name}: {case.n_particles} particles (dx = {dx:.4g}), "
        f"{p.n_steps} steps of dt = {p.dt:.4g}{p.note} to t = {p.n_steps * p.dt:.4g}, "
        f"saving every {p.save_every} steps ({p.n_frames} frames) to {out}",
        file=sys.stderr,
    )
    attrs = {
        "command": ["sphjax", *args.argv],
        "n_steps": p.n_steps,
        "save_every": p.save_every,
    }
    try:
        writer = TrajectoryWriter(
            out, case, dt=p.dt, attrs=attrs, argument="--out", overwrite=args.overwrite
        )
    except (ValueError, OSError) as err:
        raise UsageError(None, str(err)) from None
    rate_key = f"{case.name} {jax.default_backend()}{' float64' if args.float64 else ''}"
    rate_key += " native" if case.model.pair_loop == "native" else ""
    known = remembered_rate(rate_key)
    if known and case.n_particles * p.n_steps / known > LONG_RUN_SECONDS:
        print(
            f"estimated wall time: about {_duration(case.n_particles * p.n_steps / known)} "
            f"(at the {known:.3g} particle-steps/s a previous {case.name} run measured here, "
            "after compilation); Ctrl-C stops the run and keeps the frames written",
            file=sys.stderr,
        )
    bar = tqdm(total=p.n_steps, unit="step", disable=args.quiet, file=sys.stderr)
    start = time.perf_counter()
    first_chunk = []  # (time, steps) at the end of the first chunk

    def progress(n):
        now = time.perf_counter()
        if not first_chunk:
            first_chunk.append((now, n))
            running = now - start - timer.seconds(start, now)
            if n < p.n_steps and running > 0 and not known:
                left = (p.n_steps - n) / n * running
                if now - start + left > LONG_RUN_SECONDS:
                    bar.write(
                        f"estimated wall time: about {_duration(now - start + left)} "
                        f"({case.n_particles * n / running:.3g} particle-steps/s after "
                        f"compilation on the first {n} steps); Ctrl-C stops the run and keeps "
                        "the frames written",
                        file=sys.stderr,
                    )
        bar.update(n)

    with writer, CompileTimer() as timer, warnings.catch_warnings():
        warnings.showwarning = _one_line_warnings(bar)
        try:
            simulate(
                case, dt=p.dt, n_steps=p.n_steps, save_every=p.save_every, on_frames=writer,
                progress=progress, steps_per_chunk=chunk,
            )  # fmt: skip
        except SimulationError as err:
            bar.close()
            writer.set_error(str(err))
            print(
                f"sphjax run: error: {err}\nstopped at step {err.step}, particle "
                f"{err.particle}; the {writer.n_frames} frames before it are in {out}. "
                f"{_candidates(args, base)}",
                file=sys.stderr,
            )
            return EXIT_UNSTABLE
        except Exception as err:
            if not is_neighbor_overflow(err):
                raise
            bar.close()
            writer.set_error(str(err))
            print(
                f"sphjax run: error: {err}\nthe {writer.n_frames} frames before it are in {out}.",
                file=sys.stderr,
            )
            return EXIT_UNSTABLE
    bar.close()
    end = time.perf_counter()
    wall, compiling = end - start, timer.seconds(start, end)
    running = wall - compiling
    rate = f"{case.n_particles * p.n_steps / running:.3g}" if running > 0 else "?"
    if running > 0.5:  # long enough to time; remembered for the next estimate
        remember_rate(rate_key, case.n_particles * p.n_steps / running)
    lines = [
        f"done: {case.n_particles} particles, {p.n_steps} steps, {wall:.2f} s wall "
        f"({compiling:.2f} s compiling), {rate} particle-steps/s after compilation",
        f"      {writer.n_frames} frames in {out} (ParaView: open {writer.xdmf})",
    ]
    print("\n".join(lines))
    return EXIT_OK
