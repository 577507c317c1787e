"""The ``flockkit`` command: a thin layer over the public API.

Every error becomes one line on stderr and a non-zero exit (1 for errors, 2 for usage), never a
traceback.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import flockkit

from .errors import FlockkitError, ValidationError
from .registry import KINDS, describe


def _parameters(pairs) -> dict:
    """``key=value`` strings to keyword arguments; values are read as JSON when they parse."""
    params = {}
    for pair in pairs or ():
        key, sep, raw = pair.partition("=")
        if not sep or not key.isidentifier():
            raise ValidationError(f"--param expects key=value with key a Python identifier; got {pair!r}")
        try:
            params[key] = json.loads(raw)
        except json.JSONDecodeError:
            params[key] = raw
    return params


def _require_suffix(path: str, suffixes: tuple[str, ...], option: str) -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValidationError(f"{option} {path}: unknown extension {path.suffix!r}; expected {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise ValidationError(f"{option} {path}: folder {path.parent} does not exist")
    return path


def _cmd_plugins(args) -> int:
    rows = [(c.kind, c.name, c.plugin, c.distribution or "-", c.version or "-") for c in describe(args.kind)]
    header = ("kind", "name", "plugin", "distribution", "version")
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header))]
    for row in [header, *rows]:
        print("  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)).rstrip())
    return 0


def _cmd_simulate(args) -> int:
    output = _require_suffix(args.output, (".npz",), "-o")
    picture = None
    if args.picture:
        from .viz import PICTURE_SUFFIXES

        picture = _require_suffix(args.picture, PICTURE_SUFFIXES, "--picture")
    motion = flockkit.simulate(
        args.behavior,
        n_agents=args.agents,
        steps=args.steps,
        dims=args.dims,
        dt=args.dt,
        seed=args.seed,
        progress=not args.quiet and sys.stderr.isatty(),
        **_parameters(args.param),
    )
    motion.save(output)
    print(f"wrote {output}: {motion!r}")
    if picture is not None:
        from .viz import plot_motion

        plot_motion(motion, picture)
        print(f"wrote {picture}")
    return 0


def _cmd_check(args) -> int:
    from .testing import check_plugin, checks_for

    component = flockkit.get(args.kind, args.name, **_parameters(args.param))
    check_plugin(args.kind, component, name=args.name)
    print(f"{args.kind} {args.name!r}: all {len(checks_for(args.kind))} checks passed")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="flockkit", description="Animate flocks, schools, herds and small crowds.")
    parser.add_argument("--version", action="version", version=f"flockkit {flockkit.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    plugins = commands.add_parser("plugins", help="list installed plugin components")
    plugins.add_argument("--kind", choices=KINDS, help="only this kind")
    plugins.set_defaults(run=_cmd_plugins)

    simulate = commands.add_parser("simulate", help="simulate a flock and write its motion (.npz)")
    simulate.add_argument("--agents", type=int, required=True, help="number of agents (>= 1)")
    simulate.add_argument("--steps", type=int, required=True, help="number of steps (>= 1)")
    simulate.add_argument("--dims", type=int, default=2, choices=(2, 3), help="2 or 3 dimensions (default 2)")
    simulate.add_argument("--dt", type=float, default=0.1, help="seconds per step (default 0.1)")
    simulate.add_argument("--seed", type=int, default=None, help="random seed; the same seed gives the same motion")
    simulate.add_argument("--behavior", default="boids", help="behavior model (default boids)")
    simulate.add_argument("--param", action="append", metavar="KEY=VALUE", help="behavior parameter, repeatable")
    simulate.add_argument("-o", "--output", required=True, help="motion file to write (.npz)")
    simulate.add_argument("--picture", help="also draw the trajectories (.png, .pdf or .svg; needs flockkit[viz])")
    simulate.add_argument("--quiet", action="store_true", help="no progress bar")
    simulate.set_defaults(run=_cmd_simulate)

    check = commands.add_parser("check", help="run the conformance kit on an installed plugin component")
    check.add_argument("kind", choices=KINDS)
    check.add_argument("name")
    check.add_argument("--param", action="append", metavar="KEY=VALUE", help="factory parameter, repeatable")
    check.set_defaults(run=_cmd_check)
    return parser


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return args.run(args)
    except (FlockkitError, OSError, AssertionError) as exc:
        message = " ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        print(f"flockkit {args.command}: error: {message}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"flockkit {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
