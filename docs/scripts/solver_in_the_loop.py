"""Solver in the loop on the 2D Taylor-Green vortex or the dam break: a learned correction
of a coarse sphjax simulation against the coarse solver alone and the pure graph network.

    python docs/scripts/solver_in_the_loop.py --out docs/figures/sil_tg.json --seconds 300
    python docs/scripts/solver_in_the_loop.py --case dam_break --n 8 --out sil_db.json
    python docs/scripts/solver_in_the_loop.py --small --out /tmp/sil.json   # about a minute

Coarse: ``taylor_green(n=N)`` (``dam_break(n=N)``), step ``dt_c`` (its stable step); fine
reference: the same case at ``n=RATIO*N`` with ``dt_c / RATIO``.  Taylor-Green: trained on
the viscosities ``--train-nu``, evaluated on ``--test-nu``; dam break: trained on the
artificial-viscosity ``alpha`` of ``--train-alpha``, evaluated on ``--test-alpha`` (not
seen in training), probes over ``[0, 2 L] x [0, H]`` (twice the column's width, its
height).  Errors are the relative L2 probe-velocity errors of
:mod:`sphjax.surrogate.solver_in_the_loop` at coarse steps 20 and 100.  Both networks get
the same wall-clock budget (after compilation) unless ``--gns-seconds`` gives the pure
network its own; ``--iterations`` also caps it and is the length of the learning-rate
decay ``--lr`` -> ``--lr-final``.  Training runs in pieces: ``--save PREFIX`` keeps each
network, its optimiser state and its training record, ``--resume PREFIX`` continues them:
Adam's moments and step count (the schedule's step) carry on, ``--iterations`` counts
from the first piece, and pieces of one training equal one uninterrupted run of the same
arguments.  ``--restart-optimizer`` starts a new stage instead from the saved network (a
new Adam state, a schedule of its own over this piece's ``--iterations``; for a new loss,
horizon or learning rate).  The results report the totals and the whole loss curve, and
end with the wall seconds per coarse step of the solver, of each network's step and of
the fine reference over the same time.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
import optax

import sphjax
from sphjax.surrogate import solver_in_the_loop as sil


def step_costs(problem, nets: dict, repeats: int = 3) -> dict:
    """Wall seconds per coarse step (the solver alone and each trained network, after
    compiling; the best of ``repeats`` rollouts over the horizon) and per coarse-step span
    of the fine reference (``ratio`` fine steps)."""
    pc, pf = problem.conditions[0]
    n = problem.horizon
    nbrs = sil.allocate(problem)

    def best(run):
        jax.block_until_ready(run())  # compile
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            jax.block_until_ready(run())
            times.append(time.perf_counter() - t)
        return min(times)

    costs = {}
    for name, (net, mode) in {"coarse solver": (None, "correction"), **nets}.items():
        roll = eqx.filter_jit(
            lambda net, mode=mode: sil.rollout(
                problem, net, mode, problem.coarse.state, pc, n, nbrs
            )[1]
        )
        costs[name] = best(lambda roll=roll, net=net: roll(net)) / n
    fine = problem.fine
    costs["fine solver"] = (
        best(
            lambda: (
                sphjax.simulate(
                    fine, pf, n_steps=n * problem.ratio, dt=problem.dt / problem.ratio
                ).final.position
            )
        )
        / n
    )
    return costs


def read_network(parser, flag: str, prefix: str, mode: str, template):
    """The network ``PREFIX.<mode>.eqx`` an earlier ``--save`` wrote, read into
    ``template``; a network of another shape is refused in one line naming the flags."""
    try:
        return eqx.tree_deserialise_leaves(f"{prefix}.{mode}.eqx", template)
    except (RuntimeError, ValueError, TypeError):
        parser.error(
            f"{flag} {prefix}: the saved {mode} network does not fit this one; give "
            f"--latent, --message-passing, --density-input, --time-scales (and --early, "
            f"--switch for a staged one) as in the run that saved it"
        )


def learning_rate(lr, iterations=None, lr_final=None, warmup=None):
    """The training's learning rate: ``lr`` constant; with ``lr_final``, an exponential
    decay from ``lr`` to ``lr_final`` over ``iterations``; with ``warmup`` W, a linear rise
    from 0 to ``lr`` over the first W iterations, the decay (or the constant) after it, so
    that the whole schedule still spans ``iterations``."""
    if warmup is None:
        if lr_final is None:
            return lr
        return optax.exponential_decay(lr, iterations, lr_final / lr)
    after = optax.constant_schedule(lr)
    if lr_final is not None:
        after = optax.exponential_decay(lr, iterations - warmup, lr_final / lr)
    return optax.join_schedules([optax.linear_schedule(0.0, lr, warmup), after], [warmup])


def main(argv=None) -> dict:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", required=True, help="JSON file for the results")
    p.add_argument("--case", choices=["taylor_green", "dam_break"], default="taylor_green")
    p.add_argument("--n", type=int, default=12, help="coarse particles per side")
    p.add_argument("--ratio", type=int, default=2, help="fine / coarse resolution and step")
    p.add_argument("--horizon", type=int, default=100, help="coarse steps of the reference")
    p.add_argument("--unroll", type=int, default=10, help="coarse steps back-propagated")
    p.add_argument("--seconds", type=float, default=900.0, help="training budget per network")
    p.add_argument("--train-nu", type=float, nargs="+", default=[0.008, 0.012])
    p.add_argument("--test-nu", type=float, default=0.01)
    p.add_argument("--train-alpha", type=float, nargs="+", default=[0.05, 0.15])
    p.add_argument("--test-alpha", type=float, default=0.1)
    p.add_argument("--latent", type=int, default=16)
    p.add_argument(
        "--message-passing", type=int, default=2, help="message-passing steps of the network"
    )
    p.add_argument(
        "--density-input",
        action="store_true",
        help="the network also sees the density deviation (Corrector(density=True))",
    )
    p.add_argument(
        "--time-scales",
        type=float,
        nargs="+",
        default=None,
        help="TAU...: the network also sees exp(-k / tau), k the coarse steps since the "
        "start (Corrector(time_scales=...))",
    )
    p.add_argument(
        "--loss",
        choices=list(sil.LOSSES),
        default="relative",
        help="relative: mean squared relative error over the window; relative_to_coarse: "
        "each step's divided by the coarse solver's own (train(loss=...))",
    )
    p.add_argument(
        "--startup-steps",
        type=int,
        default=None,
        help="M: add the mean of the same per-step loss over the first M steps "
        "(train(startup_steps=M))",
    )
    p.add_argument(
        "--startup-weight",
        type=float,
        default=None,
        help="weight of that start-up term (default 1: the first M steps count as much "
        "as the whole window; train(startup_weight=...))",
    )
    p.add_argument(
        "--truncate",
        type=int,
        default=None,
        help="K: truncated back-propagation, the state cut from the gradient every K "
        "steps of the window (train(truncate=K))",
    )
    p.add_argument(
        "--power",
        type=float,
        default=2.0,
        help="p: the loss is the 2/p power of the mean p-th power of the per-step ratio "
        "(2: the mean square; larger: nearer the worst step; train(power=p))",
    )
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument(
        "--iterations",
        type=int,
        default=None,
        help="also cap each training at this many iterations (the schedule's length)",
    )
    p.add_argument(
        "--lr-final",
        type=float,
        default=None,
        help="decay the learning rate exponentially from --lr to this over --iterations",
    )
    p.add_argument(
        "--warmup",
        type=int,
        default=None,
        help="W: the learning rate rises linearly from 0 to --lr over the first W "
        "iterations, then decays as --lr-final says (a new Adam state takes sign-sized "
        "steps at first; a warm-up keeps them small)",
    )
    p.add_argument(
        "--early",
        default=None,
        metavar="PREFIX",
        help="a staged correction: the network PREFIX.correction.eqx (an earlier --save, "
        "trained on the start-up) corrects the steps before --switch, held fixed, and the "
        "network trained here the steps from --switch on (StagedCorrector)",
    )
    p.add_argument(
        "--switch",
        type=int,
        default=None,
        help="K: with --early, the first coarse step of the late network",
    )
    p.add_argument(
        "--gns-seconds", type=float, default=None, help="the pure network's budget (--seconds)"
    )
    p.add_argument(
        "--gravity-scale",
        action="store_true",
        help="correction of |g| dt per unit output (default 0.01 U; flows from rest)",
    )
    p.add_argument("--fine-seeds", type=int, default=4, help="fine runs averaged (disorders)")
    p.add_argument(
        "--networks", nargs="+", default=["correction", "gns"], choices=["correction", "gns"]
    )
    p.add_argument(
        "--save",
        default=None,
        help="PREFIX: write each trained network to PREFIX.<mode>.eqx and its training "
        "record (losses, iterations, seconds) to PREFIX.<mode>.json",
    )
    p.add_argument(
        "--resume",
        default=None,
        help="PREFIX of an earlier --save: continue training those networks with their "
        "optimiser state (--iterations is then the total from the first piece); the "
        "results report the totals",
    )
    p.add_argument(
        "--restart-optimizer",
        action="store_true",
        help="with --resume: a new stage from the saved network, with a new Adam state and "
        "its own schedule over this piece's --iterations (a new loss, horizon or lr)",
    )
    p.add_argument("--figure", default=None, help="PNG of the error curves (optional)")
    p.add_argument("--small", action="store_true", help="a minute-long smoke run")
    args = p.parse_args(argv)
    if args.lr_final is not None and args.iterations is None:
        p.error("--lr-final needs --iterations (the length of the decay)")
    if args.warmup is not None and (
        args.iterations is None or not 0 < args.warmup < args.iterations
    ):
        p.error(
            f"--warmup {args.warmup} needs --iterations and must lie between 0 and it "
            f"(the warm-up is part of the schedule over --iterations)"
        )
    if args.restart_optimizer and args.resume is None:
        p.error("--restart-optimizer needs --resume (the network to start the stage from)")
    if args.time_scales is not None and not all(t > 0 for t in args.time_scales):
        p.error(f"--time-scales must be positive numbers of coarse steps, got {args.time_scales}")
    if (args.early is None) != (args.switch is None):
        p.error("--early and --switch go together (the start-up network and its last step + 1)")
    if args.early is not None:
        if args.networks != ["correction"]:
            p.error("--early: a staged correction; give --networks correction")
        if not 2 <= args.switch <= args.horizon:
            p.error(f"--switch {args.switch}: give a coarse step in 2..{args.horizon} (--horizon)")
        if not Path(f"{args.early}.correction.eqx").exists():
            p.error(
                f"--early {args.early}: {args.early}.correction.eqx does not exist (give the "
                f"PREFIX of a --save with the same --latent, --message-passing and inputs)"
            )
    for mode in args.networks if args.resume is not None else ():
        for suffix in ("eqx", "json"):
            if not Path(f"{args.resume}.{mode}.{suffix}").exists():
                p.error(
                    f"--resume {args.resume}: {args.resume}.{mode}.{suffix} does not exist "
                    f"(give the PREFIX an earlier run wrote with --save and --networks {mode})"
                )
    if args.small:
        args.n, args.horizon, args.unroll, args.seconds, args.fine_seeds = 8, 20, 5, 10.0, 2

    t0 = time.perf_counter()
    make = dict(horizon=args.horizon, ratio=args.ratio, probes_per_side=16)
    if args.case == "taylor_green":
        coarse = sphjax.cases.taylor_green(n=args.n)
        # the fine reference: the mean over an ensemble of disordered starts (--fine-seeds)
        fine = [
            sphjax.cases.taylor_green(n=args.ratio * args.n, seed=s) for s in range(args.fine_seeds)
        ]
        train_c = [{"kinematic_viscosity": nu} for nu in args.train_nu]
        test_c = [{"kinematic_viscosity": args.test_nu}]
    else:
        coarse = sphjax.cases.dam_break(n=args.n)
        fine = sphjax.cases.dam_break(n=args.ratio * args.n)  # a lattice start: one run
        info = coarse.info
        make["probe_box"] = ((0.0, 2 * info["column_width"]), (0.0, info["column_height"]))
        train_c = [{"artificial_alpha": a} for a in args.train_alpha]
        test_c = [{"artificial_alpha": args.test_alpha}]
    train_problem = sil.make_problem(coarse, fine, conditions=train_c, **make)
    test_problem = sil.make_problem(coarse, fine, conditions=test_c, **make)
    setup_seconds = time.perf_counter() - t0

    report = [k for k in (20, 100) if k <= args.horizon] or [args.horizon]
    results = dict(
        settings=dict(
            vars(args),
            coarse_particles=coarse.n_particles,
            fine_particles=train_problem.fine.n_particles,
            dt_coarse=train_problem.dt,
            setup_seconds=setup_seconds,
        ),
    )
    curves = {"coarse solver": sil.errors(test_problem, None)[0]}
    names = {"correction": "solver + correction", "gns": "pure GNS"}
    trained = {}
    for mode, name in [(m, names[m]) for m in args.networks]:
        t_train = time.perf_counter()
        scale = None
        if args.gravity_scale and mode == "correction":
            scale = float(np.linalg.norm(np.asarray(coarse.params.gravity))) * train_problem.dt
        net = sil.Corrector(
            train_problem,
            jax.random.PRNGKey(0),
            mode=mode,
            latent=args.latent,
            steps=args.message_passing,
            scale=scale,
            density=args.density_input,
            time_scales=args.time_scales,
        )
        if args.early is not None:
            early = read_network(p, "--early", args.early, "correction", net)
            net = sil.StagedCorrector(early, net, args.switch)
        previous = dict(iterations=0, seconds=0.0, cpu_seconds=0.0, losses=[], pieces=0)
        lr = learning_rate(args.lr, args.iterations, args.lr_final, args.warmup)
        opt_state, iterations, seed = None, args.iterations, 0
        if args.resume is not None:
            net = read_network(p, "--resume", args.resume, mode, net)
            previous = json.loads(Path(f"{args.resume}.{mode}.json").read_text())
            saved = Path(f"{args.resume}.{mode}.opt.eqx")
            if not args.restart_optimizer and not saved.exists():
                print(f"{saved} not found: a new optimiser state, as with --restart-optimizer")
            if args.restart_optimizer or not saved.exists():
                seed = previous["iterations"]  # a new stage draws new windows
            else:
                seed = previous.get("seed", 0)  # the stage's windows, continued
                template = sil.optimizer(lr).init(eqx.filter(net, eqx.is_array))
                try:
                    opt_state = eqx.tree_deserialise_leaves(saved, template)
                except (RuntimeError, ValueError, TypeError):
                    p.error(
                        f"--resume {args.resume}: the saved optimiser state does not fit this "
                        f"run's learning rate; give --lr-final as in the run that saved it (a "
                        f"decay or a constant rate), or --restart-optimizer for a new stage"
                    )
                if iterations is not None:  # the total over the pieces
                    iterations = max(iterations - sil.completed_iterations(opt_state), 0)
        seconds = args.seconds
        if mode == "gns" and args.gns_seconds is not None:
            seconds = args.gns_seconds
        res = sil.train(
            train_problem,
            net,
            mode=mode,
            unroll=args.unroll,
            seconds=seconds,
            iterations=iterations,
            lr=lr,
            loss=args.loss,
            startup_steps=args.startup_steps,
            startup_weight=args.startup_weight,
            truncate=args.truncate,
            power=args.power,
            seed=seed,
            opt_state=opt_state,
        )
        record = dict(
            iterations=previous["iterations"] + res.iterations,
            seconds=previous["seconds"] + res.seconds,
            cpu_seconds=previous["cpu_seconds"] + res.cpu_seconds,
            losses=previous["losses"] + res.losses,
            pieces=previous["pieces"] + 1,
            seed=seed,  # the window draws of the current stage (train(seed=...))
        )
        if args.save is not None:
            Path(args.save).parent.mkdir(parents=True, exist_ok=True)
            eqx.tree_serialise_leaves(f"{args.save}.{mode}.eqx", res.net)
            eqx.tree_serialise_leaves(f"{args.save}.{mode}.opt.eqx", res.opt_state)
            Path(f"{args.save}.{mode}.json").write_text(json.dumps(record))
        curves[name] = sil.errors(test_problem, res.net, mode=mode)[0]
        trained[name] = (res.net, mode)
        results[f"{name} training"] = dict(
            record,  # the totals over every piece
            last_piece=dict(
                iterations=res.iterations, seconds=res.seconds, cpu_seconds=res.cpu_seconds
            ),
            wall_seconds_with_compile=time.perf_counter() - t_train,
            final_loss=float(np.mean(res.losses[-10:])),
            scale=float(getattr(res.net, "late", res.net).scale),  # a staged net: the late one
        )
    for name, curve in curves.items():
        results[name] = {f"error_step_{k}": float(curve[k]) for k in [0, *report]}
        results[name]["curve"] = curve.tolist()
    coarse_err = results["coarse solver"]
    results["ratio to coarse"] = {
        # step 0 is left out: both start from the same state (error 0 on a lattice start)
        name: {
            f"error_step_{k}": results[name][f"error_step_{k}"] / coarse_err[f"error_step_{k}"]
            for k in report
        }
        for name in curves
        if name != "coarse solver"
    }
    if not args.small:
        results["seconds per coarse step"] = step_costs(test_problem, trained)
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1))
    if args.figure is not None:
        from surrogate_figures import plot_sil  # the same plot as the Taylor-Green page

        plot_sil(results, Path(args.figure))
    print("seconds per coarse step", results.get("seconds per coarse step"))
    for name in curves:
        print(name, {k: round(v, 4) for k, v in results[name].items() if k != "curve"})
    return results


if __name__ == "__main__":
    main()
