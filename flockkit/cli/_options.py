"""What the commands share: the components each makes and their parameters, capability checks,
output checks, common options, the joblib backend."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import os
import sys
from pathlib import Path

import flockkit

from .. import registry
from .._atomic import check_writable
from ..errors import MissingDependencyError, ValidationError

# The components a command can make, by option (``--strategy``): the kind ``flockkit.get`` takes.
KINDS_OF_OPTIONS = {"behavior": "behavior", "metric": "metric", "builder": "builder", "strategy": "walk",
                    "segmenter": "segmenter"}  # fmt: skip

# Per command and component option, the keyword arguments the command passes itself (and the option
# that sets each; None: the command alone does): a parameter of one of these names would clash.
RESERVED = {
    "simulate": {
        "behavior": {"dt": "--dt", "n_agents": "--agents", "steps": "--steps", "seed": "--seed", "dims": "--dims",
                     "behavior": "--behavior", "progress": "--quiet", "initial": None,
                     "obstacles": "--arena or --obstacle"},
    },
    "build": {
        "builder": {"metric": "--metric", "builder": "--builder", "threshold": "--threshold", "n_jobs": "--jobs",
                    "seed": "--seed", "progress": "--quiet", "metric_params": "--metric-param", "motion": None,
                    "segmentation": "--parts", "segmenter": "--segmenter", "segmenter_params": "--segmenter-param",
                    "source": None, "features": None},
        "segmenter": {"seed": "--seed", "segmenter": "--segmenter", "source": None},
    },
    "segment": {
        "segmenter": {"n_parts": "--parts", "seed": "--seed", "segmenter": "--segmenter", "source": None},
    },
    "walk": {
        "strategy": {"duration": "--duration", "seed": "--seed", "strategy": "--strategy", "region": "--region",
                     "graph": None},
    },
}  # fmt: skip


def parse_params(pairs, reserved=None, option: str = "--param") -> dict:
    """``key=value`` strings (of `option`) to keyword arguments; values are read as JSON when they
    parse. `reserved`: names the command sets itself -> the option that sets each (None: no option)."""
    params = {}
    reserved = reserved or {}
    for pair in pairs or ():
        key, sep, raw = pair.partition("=")
        if not sep or not key.isidentifier():
            raise ValidationError(f"{option} expects key=value with key a Python identifier; got {pair!r}")
        if key in reserved:
            setter = reserved[key]
            how = f"set it with {setter}" if setter else "the command sets it itself; it is not a parameter here"
            raise ValidationError(f"{option} {key}: {how}")
        try:
            params[key] = json.loads(raw)
        except json.JSONDecodeError:
            params[key] = raw
    return params


@dataclasses.dataclass(frozen=True)
class Component:
    """A component a command makes: any installed one of its kind, named with ``--<option> NAME``
    (`default` when not given; None lets the command choose, as `shown` tells --help), configured
    with ``--<option>-param KEY=VALUE``."""

    option: str
    default: str | None = None
    shown: str | None = None

    @property
    def kind(self) -> str:
        return KINDS_OF_OPTIONS[self.option]

    @property
    def noun(self) -> str:
        """What --help calls it: the kind, and the option's word where they differ ("walk strategy")."""
        return self.kind if self.kind == self.option else f"{self.kind} {self.option}"


def add_components(parser, command: str, main: Component, *others: Component) -> None:
    """Declare the components `command` makes: for each, ``--<option> NAME`` and the repeatable
    ``--<option>-param KEY=VALUE``; ``--param`` is another name for the `main` one's parameters.
    :func:`component_params` reads them back."""
    for component in (main, *others):
        kind, noun, shown = component.kind, component.noun, component.shown or component.default
        parser.add_argument(
            f"--{component.option}", default=component.default, metavar="NAME",
            help=f"the {noun} (default {shown}); any installed {kind}: flockkit plugins --kind {kind}",
        )  # fmt: skip
        parser.add_argument(f"--{component.option}-param", dest=f"{component.option}_param", action="append",
                            metavar="KEY=VALUE", help=f"a parameter of the {noun}, repeatable")  # fmt: skip
    parser.add_argument(
        "--param", action="append", metavar="KEY=VALUE",
        help=f"a parameter of the command's main component, the {main.noun} (as --{main.option}-param), repeatable",
    )  # fmt: skip
    parser.set_defaults(components=(command, main.option))


def component_params(args, option: str) -> dict:
    """The keyword arguments of the component of `option` (declared by :func:`add_components`):
    its ``--<option>-param`` pairs, and ``--param`` for the command's main component. Names the
    command sets itself are refused, naming the option that sets them."""
    command, main = args.components
    reserved = RESERVED.get(command, {}).get(option, {})
    params = parse_params(args.param, reserved, "--param") if option == main else {}
    return {**params, **parse_params(getattr(args, f"{option}_param"), reserved, f"--{option}-param")}


def params_given(args, option: str) -> bool:
    """Whether the command line names the component of `option` or gives it parameters."""
    main = args.components[1] == option and args.param
    return bool(getattr(args, option) is not None or getattr(args, f"{option}_param") or main)


def require_capability(args, option: str, field: str, *, what: str, needed_by: dict) -> None:
    """Refuse, before anything is made, the options that need the component of `option` to
    declare ``Capabilities.<field>`` (`needed_by`: option -> whether the command line gives it):
    one line naming the options, the component, the capability, and the installed components of
    its kind that declare it. `what` names what the options ask of the component ("obstacles")."""
    given = " and ".join(name for name, present in needed_by.items() if present)
    if not given:
        return
    kind, name = KINDS_OF_OPTIONS[option], getattr(args, option)
    try:
        registry.require(kind, name, field, f"{what} ({given})")
    except ValidationError as exc:
        declaring = [n for n in registry.available(kind) if getattr(registry.capabilities_of(kind, n), field)]
        instead = (f"choose one that does with --{option} (installed: {', '.join(declaring)})" if declaring
                   else f"no installed {kind} declares it")  # fmt: skip
        raise ValidationError(f"{exc}; {instead}, or leave out {given}") from None


def require_parameter(args, option: str, parameter: str, given_as: str) -> None:
    """Refuse `given_as` (an option given on the command line that sets `parameter`) when the
    component of `option` does not take that parameter: one line naming the option, the
    component, and the installed components of its kind that take it."""
    kind, name = KINDS_OF_OPTIONS[option], getattr(args, option)
    if name not in registry.available(kind):
        return  # flockkit.get names the unknown component and what is installed
    taking = [c.name for c in registry.describe(kind) if registry.takes(kind, c.name, parameter)]
    if name in taking:
        return
    instead = (f"choose one that does with --{option} (installed: {', '.join(taking)})" if taking
               else f"no installed {kind} takes it")  # fmt: skip
    raise ValidationError(f"{given_as}: {kind} {name!r} takes no {parameter}=; {instead}")


def require_suffix(path: str, suffixes: tuple[str, ...], option: str) -> Path:
    """The output `path`, checked before any work: a known suffix, and a file can be made there."""
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise ValidationError(f"{option} {path}: unknown extension {path.suffix!r}; expected {' or '.join(suffixes)}")
    if not path.parent.is_dir():
        raise ValidationError(f"{option} {path}: folder {path.parent} does not exist")
    return check_writable(path)


def shows_progress(args) -> bool:
    return not args.quiet and sys.stderr.isatty()


def parse_region(text: str, option: str = "--region"):
    """box:x0,y0,x1,y1 (or 3D: 6 numbers), ball:cx,cy[,cz],r, polygon:x0,y0,x1,y1,..."""
    kind, sep, numbers = text.partition(":")
    try:
        values = [float(v) for v in numbers.split(",")] if sep else []
    except ValueError:
        values = []
    if kind == "box" and len(values) in (4, 6):
        half = len(values) // 2
        return flockkit.Box(lower=values[:half], upper=values[half:])
    if kind == "ball" and len(values) in (3, 4):
        return flockkit.Ball(center=values[:-1], radius=values[-1])
    if kind == "polygon" and len(values) >= 6 and len(values) % 2 == 0:
        return flockkit.Polygon(vertices=[values[i : i + 2] for i in range(0, len(values), 2)])
    raise ValidationError(
        f"{option} {text!r}: expected box:x0,y0,x1,y1 (or 6 numbers in 3D), ball:cx,cy[,cz],r or "
        "polygon:x0,y0,x1,y1,x2,y2,..."
    )


MESH_SUFFIXES = (".glb", ".gltf", ".usda", ".usdc", ".usdz", ".usd", ".obj")


def is_mesh_file(path: str) -> bool:
    """Whether `path` names an animated-mesh file that :func:`read_source` reads with
    flockkit.io (glTF, USD, an OBJ file, a folder of them or a glob), not a flockkit .npz."""
    glob = not Path(path).exists() and any(c in path for c in "*?[")
    return Path(path).suffix.lower() in MESH_SUFFIXES or Path(path).is_dir() or glob


def is_mesh_source(path: str) -> bool:
    """Whether :func:`read_source` reads `path` as an AnimatedMesh (a mesh file, or a flockkit
    mesh .npz) rather than a Motion: what a command that draws either asks."""
    from .._npzfile import kind_of

    return is_mesh_file(path) or kind_of(path) == "mesh"


def read_source(path: str, clip=None, fps=None, allow_outside=False, up=None, meters_per_unit=None):
    """A Motion or an AnimatedMesh: a flockkit .npz of either, or an animated-mesh file (glTF,
    USD, an OBJ folder or glob) read at `fps` (default 30) for `clip`. With `up` or
    `meters_per_unit` (--up, --meters-per-unit), a mesh is turned into flockkit's axes (z up,
    metres), these stating its file's up axis and unit where the file is silent or wrong."""
    from .._npzfile import kind_of

    convert = up is not None or meters_per_unit is not None
    if is_mesh_file(path):
        mesh = flockkit.io.read_mesh_animation(path, clip=clip, fps=30.0 if fps is None else fps,
                                               allow_outside=allow_outside)  # fmt: skip
    elif kind_of(path) == "mesh":
        mesh = flockkit.AnimatedMesh.load(path)
    else:
        if convert:
            raise ValidationError(f"--up, --meters-per-unit: {path} is a motion, not an animated mesh")
        return flockkit.Motion.load(path)
    if not convert:
        return mesh
    return mesh.to_flockkit_axes(up_axis=up, meters_per_unit=_unit(meters_per_unit))


def _unit(text):
    """--meters-per-unit as to_flockkit_axes takes it: a number, or a unit's name ("cm")."""
    try:
        return None if text is None else float(text)
    except ValueError:
        return text


def check_folder(path) -> Path:
    """The output folder `path` (-o), checked before any work: not a file, and its parent exists."""
    folder = Path(path)
    if folder.exists() and not folder.is_dir():
        raise ValidationError(f"-o must be a folder; {folder} is a file")
    if not folder.parent.is_dir():
        raise ValidationError(f"-o {folder}: folder {folder.parent} does not exist")
    return folder


@contextlib.contextmanager
def staged_folder(folder: Path):
    """Yield a new temporary folder beside `folder` to write a command's files into; when the
    block succeeds they are moved into `folder` (made if missing), each replacing its namesake,
    and otherwise removed with the temporary folder: a failure halfway leaves no file behind."""
    import shutil
    import tempfile

    folder = check_folder(folder)
    staging = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        yield staging
        folder.mkdir(exist_ok=True)
        for file in sorted(staging.iterdir()):
            os.replace(file, folder / file.name)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


@contextlib.contextmanager
def joblib_backend(args):
    """Run the command's parallel work on the joblib backend `--backend` names (with `--jobs`
    workers, default all): dask (a LocalCluster, or the scheduler at `--scheduler`), ray (a local
    Ray, or the cluster at `--scheduler`), loky, threading. Without it, joblib's default."""
    import joblib

    if args.backend is None:
        yield
        return
    workers = -1 if args.jobs is None else args.jobs
    if args.backend == "dask":
        try:
            from distributed import Client
        except ImportError:
            raise MissingDependencyError(
                "--backend dask needs dask.distributed: pip install 'flockkit[scale]'"
            ) from None
        with Client(args.scheduler) if args.scheduler else Client(), joblib.parallel_config("dask", n_jobs=workers):
            yield
    elif args.backend == "ray":
        try:
            import ray
            from ray.util.joblib import register_ray
        except ImportError:
            raise MissingDependencyError("--backend ray needs ray: pip install 'flockkit[scale]'") from None
        register_ray()
        ray.init(address=args.scheduler, include_dashboard=False, log_to_driver=False)
        try:
            with joblib.parallel_config("ray", n_jobs=workers):
                yield
        finally:
            ray.shutdown()
    else:
        with joblib.parallel_config(args.backend, n_jobs=workers):
            yield


def pixel_size(text: str) -> tuple[int, int]:
    """--size WIDTHxHEIGHT in pixels."""
    width, sep, height = text.lower().partition("x")
    if not (sep and width.isdigit() and height.isdigit()):
        raise ValidationError(f"--size {text!r}: expected WIDTHxHEIGHT in pixels, e.g. 800x600")
    return int(width), int(height)


def add_output(parser, help: str) -> None:
    parser.add_argument("-o", "--output", required=True, help=help)


def add_quiet(parser) -> None:
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def add_param(parser, what: str) -> None:
    parser.add_argument("--param", action="append", metavar="KEY=VALUE", help=f"{what} parameter, repeatable")


def add_scale_out(parser) -> None:
    parser.add_argument("--jobs", type=int, help="parallel workers (-1: all; default 1, or all with --backend)")
    parser.add_argument(
        "--backend", choices=("loky", "threading", "dask", "ray"), help="joblib backend (dask, ray: flockkit[scale])"
    )
    parser.add_argument("--scheduler", metavar="ADDRESS", help="with --backend dask or ray: the cluster to use")


def add_mesh_options(parser) -> None:
    parser.add_argument("--clip", help="the clip of an animated-mesh file (default: its first)")
    parser.add_argument("--fps", type=float, help="frames per second to sample an animated-mesh file at (default 30)")
    parser.add_argument(
        "--up", choices=("x", "y", "z"),
        help="turn an animated mesh into flockkit's axes (z up, metres), its file's up axis being this one "
             "(default: what the file says; glTF: y)",
    )  # fmt: skip
    parser.add_argument(
        "--meters-per-unit", metavar="UNIT",
        help="turn an animated mesh into flockkit's axes (z up, metres), its file's unit being this many metres "
             "(a number, or m, cm, mm, in, ft, ...; the glTF Fox: cm); what a scene's templates need to stand "
             "upright at true size",
    )  # fmt: skip
    add_allow_outside(parser)


def add_allow_outside(parser) -> None:
    parser.add_argument(
        "--allow-outside",
        action="store_true",
        help="let the input refer to files outside its folder (absolute paths, ..; see docs/security.md)",
    )
