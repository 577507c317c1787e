"""``flockkit plugins`` and ``flockkit check``: the installed components and the conformance kit."""

from __future__ import annotations

import flockkit

from ..errors import ValidationError
from ..registry import KINDS, describe
from ._options import (
    add_param,
    add_quiet,
    parse_params,
    shows_progress,
)


def _cmd_plugins(args) -> int:
    rows = [(c.kind, c.name, c.plugin, c.distribution or "-", c.version or "-") for c in describe(args.kind)]
    header = ("kind", "name", "plugin", "distribution", "version")
    widths = [max(len(str(row[i])) for row in [header, *rows]) for i in range(len(header))]
    for row in [header, *rows]:
        print("  ".join(str(cell).ljust(width) for cell, width in zip(row, widths)).rstrip())
    return 0


def _cmd_check(args) -> int:
    from ..testing import check_plugin

    component = flockkit.get(args.kind, args.name, **parse_params(args.param))
    report = check_plugin(
        args.kind, component, name=args.name, partners=_partners(args.partner), progress=shows_progress(args)
    )
    print(f"{args.kind} {args.name!r}: {report.summary()}")
    return 0


def _partners(pairs) -> dict:
    """--partner metric=NAME, behavior=NAME (made with dt = 0.1 s, as the kit's motions) or
    graph=FILE.npz."""
    partners = {}
    for pair in pairs or ():
        key, sep, value = pair.partition("=")
        if not sep or key not in ("metric", "behavior", "graph"):
            raise ValidationError(f"--partner expects metric=NAME, behavior=NAME or graph=FILE.npz; got {pair!r}")
        if key == "graph":
            partners[key] = flockkit.MotionGraph.load(value)
        else:
            partners[key] = flockkit.get(key, value, **({"dt": 0.1} if key == "behavior" else {}))
    return partners


def _plugins_arguments(parser) -> None:
    parser.add_argument("--kind", choices=KINDS, help="only this kind")


def _check_arguments(parser) -> None:
    parser.add_argument("kind", choices=KINDS)
    parser.add_argument("name")
    add_param(parser, "factory")
    parser.add_argument(
        "--partner",
        action="append",
        metavar="KIND=NAME",
        help="partner component of the checks: metric=NAME (builders), behavior=NAME (proposals), "
        "graph=FILE.npz (walks); default: the built-in, or the kit's own graph",
    )
    add_quiet(parser)


# command -> (help, arguments, run)
COMMANDS = {
    "plugins": ("list installed plugin components", _plugins_arguments, _cmd_plugins),
    "check": ("run the conformance kit on an installed plugin component", _check_arguments, _cmd_check),
}
