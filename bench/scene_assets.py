"""Scenes of real assets (paper 002): N objects for 2 minutes at 30 fps, half Foxes walking in
place (Fox.glb's Walk clip, in metres, parts by the default segmenter, each a looping graph with
phase shifts, its arrow held: forward at 0.6) and half MorphStressTest's Individuals clip (its
arrow keyframed 0.3 -> 0.9 -> 0.3 over the clip), built as ``flockkit build --layers`` and
``flockkit scene`` build them, following a wind that blows east and changes strength (0.6, 0.4,
0.8, 0.6 at each quarter), ``headings = "aligned"``, the region 3 footprint diagonals a side per
object. Prints the seconds of each stage: reading and building the layers (once), placement,
targets, the walks per template part (first pass), de-synchronisation (rounds of walks again),
and the synthesis of vertices (SceneAnimation.motion: the object's walk played and placed in the
world, scaled, turned and moved, by one compiled pass, only the scene's frames; timed over a
sample of objects, the best of 3 calls each, and scaled to all of them, plus what is made once
per template and process, its "set-up"; a scene is never held in memory whole) in
milliseconds per second of output per 1 000 vertices against its peer (flockkit.synthesize, every
frame the walk plays, then placed by numpy: one matrix product over all points and frames and
the offset added in place) and the largest difference between the two relative to the object's
size, with ``--profile`` the functions where
the walks spend their time (cProfile, one job), with ``--check N`` N objects walked by the
annotated walk's compiled loops and by its Python reference, which must be the same.

    python bench/scene_assets.py --objects 60 --jobs 2 [--data ../shared/data] [--profile] [--check 4]
"""

from __future__ import annotations

import argparse
import contextlib
import cProfile
import os
import pstats
import resource
import time
import warnings
from pathlib import Path

import attrs
import numpy as np
from timing import timed  # bench/timing.py: the scripts run from bench/

import flockkit
from flockkit.scene import Arrow, FlowField
from flockkit.scene.desync import largest_in_step, pairs_in_step
from flockkit.scene.templates import footprint, template_view


def templates(data: Path):
    fox = flockkit.io.read_mesh_animation(data / "fox-gltf" / "Fox.glb", clip="Walk", fps=30.0)
    fox = fox.to_flockkit_axes(meters_per_unit="cm")
    fox_layers = flockkit.build_layers(fox, seed=0)
    held = flockkit.Features.from_keyframes([[0, [0, -0.6]]], n_frames=fox.motion.n_frames, dt=fox.motion.dt)
    morph = flockkit.io.read_mesh_animation(data / "morph-stress-test-gltf" / "MorphStressTest.gltf",
                                            clip="Individuals", fps=30.0)  # fmt: skip
    morph_layers = flockkit.build_layers(morph, seed=0)
    swelling = flockkit.Features.from_keyframes([[0, [0.3, 0]], [4.6, [0.9, 0]], [9.3, [0.3, 0]]],
                                                n_frames=morph.motion.n_frames, dt=morph.motion.dt)  # fmt: skip
    return [attrs.evolve(fox_layers, features=held), attrs.evolve(morph_layers, features=swelling)]


def scene_of(layers, count: int, jobs: int, duration: float = 120.0) -> flockkit.Scene:
    diagonal = max(2 * np.linalg.norm(footprint(t)[1]) for t in layers)
    side = 3.0 * diagonal * np.sqrt(count)
    region = flockkit.Polygon(vertices=[[0, 0], [side, 0], [side, side], [0, side]])
    q = duration / 4
    keyframes = [(0, [0.6, 0]), (q, [0.4, 0]), (2 * q, [0.8, 0]), (3 * q, [0.6, 0])]
    wind = FlowField(arrows=[Arrow(position=[side / 2, side / 2], keyframes=keyframes)])
    return flockkit.Scene(templates=layers, region=region, counts=[count // 2, count - count // 2],
                          duration=duration, constraints=[wind], seed=1, headings="aligned", n_jobs=jobs)  # fmt: skip


def cpu_seconds() -> float:
    """User + system CPU seconds of this process and its workers (live ones through psutil, where
    it is installed, and those ended and waited for): less sensitive to other work on the
    machine than the wall clock."""
    own, ended = (resource.getrusage(who) for who in (resource.RUSAGE_SELF, resource.RUSAGE_CHILDREN))
    total = own.ru_utime + own.ru_stime + ended.ru_utime + ended.ru_stime
    try:
        import psutil
    except ImportError:
        return total
    for child in psutil.Process().children(recursive=True):
        with contextlib.suppress(psutil.Error):
            times = child.cpu_times()
            total += times.user + times.system
    return total


def stages(scene: flockkit.Scene, sample: int) -> dict:
    """Scene.synthesize's stages, timed one by one (the same calls, in the same order)."""
    times = {}
    cpu = cpu_seconds()
    clock = time.perf_counter()
    placement = scene.place()
    times["placement"], clock = time.perf_counter() - clock, time.perf_counter()
    targets = scene.targets(placement)
    times["targets"], clock = time.perf_counter() - clock, time.perf_counter()
    seeds = np.random.SeedSequence(scene.seed).spawn(2)[1].spawn(placement.n_objects)
    animation = flockkit.SceneAnimation(templates=scene.templates, placement=placement,
                                        walks=[None] * placement.n_objects, dt=scene.frame_time,
                                        n_frames=scene.n_frames, constraints=scene.constraints,
                                        region=scene.region)  # fmt: skip
    neighbours = animation.neighbours()
    walks, frames, rounds = scene._first_walks(placement, targets, seeds, neighbours, None)
    times["walks"], clock = time.perf_counter() - clock, time.perf_counter()
    animation = attrs.evolve(animation, walks=walks)
    before = largest_in_step(frames, neighbours), pairs_in_step(frames, neighbours)
    walks, again = scene._desynchronise(animation, targets, seeds, frames, neighbours, None)
    times["de-sync"], clock = time.perf_counter() - clock, time.perf_counter()
    times["cpu"] = cpu_seconds() - cpu  # placement to de-sync, user + system, workers included
    animation = attrs.evolve(animation, walks=walks)
    # once per template and process: the compiled pass loaded from its cache and what a template's
    # synthesis reads whatever the walk (its parts' sources, seam shares) made
    clock = time.perf_counter()
    for kind in range(len(scene.templates)):
        members = np.flatnonzero(placement.templates == kind)
        if len(members):
            animation.motion(int(members[0]))
    setup = time.perf_counter() - clock
    picked = np.linspace(0, placement.n_objects - 1, min(sample, placement.n_objects)).round().astype(int)
    vertices, took, peer, gap = 0, 0.0, 0.0, 0.0
    for i in picked:
        ours, seconds = timed(lambda i=int(i): animation.motion(i), repeat=3)
        plain, peer_seconds = timed(lambda i=int(i): placed_plainly(animation, i), repeat=3)
        vertices, took, peer = vertices + ours.n_agents, took + seconds, peer + peer_seconds
        gap = max(gap, float(np.abs(ours.positions - plain).max() / np.ptp(ours.positions[0], axis=0).max()))
    times["synthesis set-up"] = setup
    times["synthesis (scaled)"] = setup + took * placement.n_objects / len(picked)
    times["first rounds"], times["walked again"] = rounds, again
    times["in step before"], times["pairs before"] = before
    times["in step after"], times["pairs after"] = (
        largest_in_step(frames, neighbours),
        pairs_in_step(frames, neighbours),
    )
    times["ms per output s per 1k vertices"] = took * 1000 / (scene.duration * vertices / 1000)
    times["peer ms per output s per 1k vertices"] = peer * 1000 / (scene.duration * vertices / 1000)
    times["max difference / size"] = gap
    return times


def placed_plainly(animation, i: int) -> np.ndarray:
    """The peer of ``animation.motion(i)`` for an object that stands: the object's walk played
    by flockkit.synthesize (every frame it plays), cut to the scene's frames, then placed by numpy
    as one matrix product over all points of all frames, ``(p - center) @ (scale turn).T + where``,
    and the offset added in place."""
    from flockkit.scene.placement import heading_turn

    placement, kind = animation.placement, animation.placement.templates[i]
    template = animation.templates[kind]
    played = flockkit.synthesize(template, animation.walks[i]).positions[: animation.n_frames]
    d = played.shape[2]
    center = footprint(template)[0]
    matrix = placement.scales[i] * heading_turn(placement.headings[i], d)
    where = np.zeros(d)
    where[:2] = placement.positions[i]
    out = played.reshape(-1, d) @ matrix.T
    out += where - matrix @ center
    return out.reshape(played.shape)


def check(scene: flockkit.Scene, objects: int) -> str:
    """Walks `objects` objects (spread over the scene) with the annotated walk's compiled loops
    and with its Python reference (annotated._COMPILED = False), first without and then avoiding
    their neighbours' frames, here in one process: raises unless every walk is the same, and
    says the seconds each side took per object and walk."""
    from flockkit_walks import annotated

    from flockkit.scene.scene import _walk_object

    placement = scene.place()
    targets = scene.targets(placement)
    seeds = np.random.SeedSequence(scene.seed).spawn(2)[1].spawn(placement.n_objects)
    picked = np.linspace(0, placement.n_objects - 1, min(objects, placement.n_objects)).round().astype(int)
    walks = [_walk_object(scene, i, placement, targets[i], int(seeds[i].generate_state(1)[0]), None)
             for i in range(placement.n_objects)]  # fmt: skip
    animation = flockkit.SceneAnimation(templates=scene.templates, placement=placement, walks=walks,
                                        dt=scene.frame_time, n_frames=scene.n_frames)  # fmt: skip
    frames, near = animation.source_frames(), animation.neighbours()
    seconds = {}
    made = {}
    for compiled in (True, False):
        annotated._COMPILED = compiled
        clock = time.perf_counter()
        made[compiled] = [
            _walk_object(scene, int(i), placement, targets[i], int(seeds[i].generate_state(2)[1]), avoid)
            for i in picked
            for avoid in (None, frames[near[i]] if len(near[i]) else None)
        ]
        seconds[compiled] = (time.perf_counter() - clock) / len(made[compiled])
    annotated._COMPILED = True
    if made[True] != made[False]:
        raise AssertionError("compiled walks differ from the reference's")
    return (
        f"check: {len(made[True])} walks of {len(picked)} objects (without and avoiding neighbours) the same "
        f"compiled and in Python; {seconds[True]:.3f} s against {seconds[False]:.3f} s per object's walk"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", default=str(Path(__file__).resolve().parents[2] / "shared" / "data"))
    parser.add_argument("--objects", type=int, nargs="+", default=[60])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=120.0)
    parser.add_argument("--sample", type=int, default=10, help="objects whose vertices are synthesized")
    parser.add_argument("--profile", action="store_true")
    parser.add_argument("--check", type=int, default=0,
                        help="objects walked compiled and by the Python reference, which must be the same")  # fmt: skip
    args = parser.parse_args()
    warnings.simplefilter("ignore", flockkit.errors.FlockkitWarning)
    clock = time.perf_counter()
    layers = templates(Path(args.data))
    print(f"templates read and built in {time.perf_counter() - clock:.1f} s: " + "; ".join(
        f"{t.source.n_agents} points, {t.n_parts} parts of {[len(g.nodes) for g in t.graphs]} nodes"
        for t in layers))  # fmt: skip
    for count in args.objects:
        scene = scene_of(layers, count, args.jobs, args.seconds)
        if args.profile:
            profile = cProfile.Profile()
            profile.enable()
        clock = time.perf_counter()
        figures = stages(scene, args.sample)
        total = time.perf_counter() - clock
        if args.profile:
            profile.disable()
            pstats.Stats(profile).sort_stats("tottime").print_stats(25)
        walking = figures["placement"] + figures["targets"] + figures["walks"] + figures["de-sync"]
        cpu = figures.pop("cpu")
        print(f"{count} objects x {args.seconds:g} s, {args.jobs} jobs: " + ", ".join(
            f"{k} {v:.3g}" + (" s" if isinstance(v, float) and k[0] not in "ipm" else "")
            for k, v in figures.items()) + f"; scene (placement to de-sync) {walking:.1f} s = "
              f"{1000 * walking / count:.0f} ms per object, CPU (user + system, workers included) {cpu:.1f} s = "
              f"{1000 * cpu / count:.0f} ms per object; all {total:.1f} s; load average "
              f"{' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)  # fmt: skip
    if args.check:
        print(check(scene_of(layers, max(args.objects), args.jobs, args.seconds), args.check), flush=True)
    parts = [(k, g) for k, t in enumerate(layers) for g in template_view(t).graphs]
    shown = [(k, len(g.nodes), len(g.transitions), int(np.count_nonzero(g.shifts)), g.period) for k, g in parts]
    print("template parts (template, nodes, transitions, phase shifts, period):", shown)


if __name__ == "__main__":
    main()
