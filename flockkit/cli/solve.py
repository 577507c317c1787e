"""``flockkit solve``: a constrained-animation scenario (paper 004)."""

from __future__ import annotations

import flockkit

from ..errors import FlockkitError
from ._options import (
    add_output,
    add_quiet,
    add_scale_out,
    joblib_backend,
    require_suffix,
    shows_progress,
)


def _cmd_solve(args) -> int:
    from ..constrained import load_scenario

    output = require_suffix(args.output, (".npz",), "-o")
    problem, settings = load_scenario(args.scenario)
    for option in ("iterations", "refine", "starts", "chains", "seed"):
        if getattr(args, option) is not None:
            settings[option] = getattr(args, option)
    from ..constrained.sampler import unmet

    with joblib_backend(args):
        solution = flockkit.solve(problem, n_jobs=args.jobs, progress=shows_progress(args), **settings)
    solution.motion.save(output)
    rates = ", ".join(f"{name} {rate:.0%}" for name, rate in sorted(solution.acceptance.items())) or "none"
    print(f"wrote {output}: {solution.motion!r}")
    print(
        f"log g {solution.log_g[0]:.6g}; largest constraint residual {max(solution.residuals, default=0.0):.3g}; "
        f"accepted: {rates}"
    )
    missed = unmet(problem, solution.motion)
    if missed:
        index, residual, limit = max(missed, key=lambda m: m[1] - m[2])
        kind = type(problem.constraints[index]).__name__
        raise Unmet(
            f"{len(missed)} constraint(s) not met; the worst is constraints[{index}] ({kind} at "
            f"t={problem.constraints[index].time:g}), off by {residual:.3g} (tolerance {limit:.3g}); {output} holds "
            "the closest motion found: the scenario asks for more than the behavior model can do there"
        )
    return 0


class Unmet(FlockkitError):
    """solve wrote its best motion, but it misses a constraint: exit status 3."""


def _solve_arguments(parser) -> None:
    parser.add_argument("scenario", help="scenario file (.toml; see examples/scenarios)")
    add_output(parser, "motion file to write (.npz)")
    parser.add_argument("--iterations", type=int, help="sampler iterations (default: the scenario's, else 1000)")
    parser.add_argument(
        "--refine", type=int, help="least-squares steps before sampling (default: the scenario's, else 40)"
    )
    parser.add_argument(
        "--starts",
        type=int,
        help="initial trajectories drawn per chain, the best kept (default: the scenario's, else 1)",
    )
    parser.add_argument("--chains", type=int, help="independent chains")
    parser.add_argument("--seed", type=int, help="random seed")
    add_scale_out(parser)
    add_quiet(parser)


# command -> (help, arguments, run)
COMMANDS = {
    "solve": ("solve a constrained-animation scenario (.toml) and write the motion", _solve_arguments, _cmd_solve),
}
