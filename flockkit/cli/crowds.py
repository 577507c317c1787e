"""``flockkit crowd``: skeletal characters driven along trajectories (paper 003)."""

from __future__ import annotations

import json

from ._options import add_allow_outside, add_quiet, check_folder, staged_folder


def _character_mesh(scene_path, allow_outside: bool):
    """The skinned mesh of the scene's [character] clips where they are a glTF character with a
    skin (``read_skin``), else None (a BVH take, a skeleton without a mesh)."""
    import tomllib
    from pathlib import Path

    from .._files import confined
    from ..errors import ValidationError
    from ..io.skin import read_skin

    path = Path(scene_path)
    clips = tomllib.loads(path.read_text())["character"]["clips"]
    source = confined(path.parent, clips, source=path, where="character.clips", allow_outside=allow_outside, uri=False)
    if source.suffix.lower() not in (".glb", ".gltf"):
        return None
    try:
        return read_skin(source, allow_outside=allow_outside)
    except ValidationError:  # no skin, or no mesh the skeleton moves
        return None


def _cmd_crowd(args) -> int:
    from ..crowd.file import read_crowd_scene
    from ..crowd.record import export_usd, record

    folder = check_folder(args.output)
    scene = read_crowd_scene(args.scene, allow_outside=args.allow_outside)
    if not args.no_usd:  # fail before the run, not after it, when usd-core is missing
        from ..io.usd import require_usd_core

        require_usd_core()
    mesh = None if args.no_usd else _character_mesh(args.scene, args.allow_outside)
    driver = scene.driver()
    recording = record(driver, scene.seconds, agents=range(scene.record))
    names = ([] if args.no_usd else ["crowd.usdc"]) + ([] if args.no_pictures else ["crowd.gif"]) + ["crowd.json"]
    summary = {
        "agents": driver.crowd.n_agents,
        "recorded": scene.record,
        "frames": recording.n_frames,
        "streams": [s.name for s in scene.streams],
        "stream switches": driver.switches,
        "memory (bytes)": driver.crowd.pool.memory(),
    }
    with staged_folder(folder) as staging:  # every file, or none
        if not args.no_usd:  # the same run again, its streams shared by the agents that read them
            export_usd(scene.driver(), staging / "crowd.usdc", scene.seconds, agents=range(scene.record), mesh=mesh)
        if not args.no_pictures:
            from ..viz import animate_recording

            animate_recording(recording, staging / "crowd.gif", progress=not args.quiet)
        (staging / "crowd.json").write_text(json.dumps(summary, indent=2))
    written = [folder / name for name in names]
    print(f"wrote {', '.join(str(p) for p in written)}: {summary['agents']} agents, {summary['frames']} frames, "
          f"{summary['stream switches']} stream switches")  # fmt: skip
    return 0


def _crowd_arguments(parser) -> None:
    parser.add_argument("scene", help="crowd scene file (.toml; see docs/concepts.md, massive crowds)")
    parser.add_argument("-o", "--output", required=True, help="folder to write crowd.usdc, crowd.gif, crowd.json")
    parser.add_argument("--no-usd", action="store_true", help="skip the USD export (needs flockkit[usd])")
    parser.add_argument("--no-pictures", action="store_true", help="skip the animation (needs flockkit[viz])")
    add_allow_outside(parser)
    add_quiet(parser)


# command -> (help, arguments, run)
COMMANDS = {
    "crowd": (
        "drive a crowd of skeletal characters along trajectories (.toml); write USD (skinned where the character "
        "is a glTF skin), animation, summary",
        _crowd_arguments,
        _cmd_crowd,
    ),
}
