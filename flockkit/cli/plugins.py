"""``flockkit plugins``, ``flockkit check`` and ``flockkit new-plugin``: the installed components,
the conformance kit, and a ready distribution to start a new plugin from."""

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


def _cmd_new_plugin(args) -> int:
    from ..testing.template import write_plugin

    path = write_plugin(args.kind, args.name, args.directory)
    print(f"wrote {path}: a {args.kind} plugin {args.name!r}")
    print(f'next: cd {path} && pip install -e ".[test]" && pytest')
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


def _new_plugin_arguments(parser) -> None:
    # KIND is checked by write_plugin, not by argparse, so that a wrong one is a one-line error
    parser.add_argument("kind", metavar="KIND", help=f"the extension kind: {', '.join(KINDS)}")
    parser.add_argument(
        "name", metavar="NAME", help="the component's registered name: lower-case words joined by - or _"
    )
    parser.add_argument(
        "directory",
        metavar="DIR",
        nargs="?",
        help="the folder to write (default: ./flockkit-NAME); it must not exist, or be empty",
    )


# command -> (help, arguments, run)
COMMANDS = {
    "plugins": ("list installed plugin components", _plugins_arguments, _cmd_plugins),
    "check": ("run the conformance kit on an installed plugin component", _check_arguments, _cmd_check),
    "new-plugin": (
        "write a ready distribution for a new plugin of any kind",
        _new_plugin_arguments,
        _cmd_new_plugin,
    ),
}
