"""Every value type a kind receives or returns has a strategy, and each draws valid values."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument

import flockkit
from flockkit.graphs import synthesize_graph
from flockkit.kinds import KINDS
from flockkit.scene import Features, arrow_keyframes
from flockkit.skeleton import stream_times
from flockkit.testing import inputs
from flockkit.testing import strategies as fst

# value type -> the strategy that draws it (Clip and Transition come inside motion graphs)
DRAWN_BY = {
    "State": "states",
    "Motion": "motions",
    "Configuration": "configurations",
    "Alignment": "alignments",
    "MotionGraph": "motion_graphs",
    "Clip": "motion_graphs",
    "Transition": "motion_graphs",
    "Walk": "walks",
    "ProposalContext": "proposal_contexts",
    "Proposal": "proposals",
    "Problem": "problems",
    "Segmentation": "segmentations",
    "MeshSkin": "skinned_meshes",
    "Pose": "poses",
    "Event": "events",
    "Skeleton": "skeletons",
    "SkeletalClip": "skeletal_clips",
    "Channel": "channels",
}


@pytest.mark.parametrize("path", sorted({p for k in KINDS.values() for p in (*k.receives, *k.returns)}))
def test_every_value_a_kind_handles_has_a_strategy(path):
    assert DRAWN_BY[path.rpartition(".")[2]] in fst.__all__


def test_all_names_exist():
    assert all(hasattr(fst, name) for name in fst.__all__) and len(set(fst.__all__)) == len(fst.__all__)


# -- helpers: ties, coincidence and rank within rounding ------------------------------------------


def _ties(values, scale):
    """Whether two of `values` are equal within rounding, relative to `scale`."""
    ordered = np.sort(np.asarray(values, dtype=float))
    return bool(np.any(np.diff(ordered) <= 1e-9 * scale))


def _coincident(positions, scale):
    """Per agent, whether another agent is on its spot (within rounding)."""
    gaps = np.linalg.norm(positions[:, None] - positions[None], axis=-1) + np.diag(np.full(len(positions), np.inf))
    return gaps.min(axis=1) <= 1e-9 * scale


def _radii(config):
    return np.linalg.norm(config.positions - config.center_of_mass(), axis=1)


def _rank(positions, scale):
    centered = positions - positions.mean(axis=0)
    return int(np.sum(np.linalg.svd(centered, compute_uv=False) > 1e-9 * scale))


def _proper(rotation):
    d = rotation.shape[0]
    return np.allclose(rotation @ rotation.T, np.eye(d), atol=1e-12) and np.isclose(np.linalg.det(rotation), 1.0)


# -- configurations and what metrics receive ----------------------------------------------------


@settings(max_examples=30, deadline=None)
@given(fst.alignments())
def test_alignments_are_proper(alignment):
    assert _proper(alignment.rotation)
    assert sorted(alignment.assignment) == list(range(len(alignment.assignment))) and alignment.distance >= 0
    assert alignment.translation.shape == (alignment.rotation.shape[0],)


@settings(max_examples=40, deadline=None)
@given(fst.symmetric_configurations())
def test_symmetric_configurations_tie(config):
    scale = np.abs(config.positions).max() + 1.0
    assert config.n_agents <= 2 or _ties(_radii(config), scale)


@settings(max_examples=40, deadline=None)
@given(fst.tied_configurations(min_agents=2, max_agents=12, max_coordinate=5.0, max_speed=1.5))
def test_tied_configurations_are_degenerate_and_bounded(config):
    """Every one ties, coincides or lies on a line: what random coordinates almost never do."""
    scale = np.abs(config.positions).max() + 1.0
    degenerate = (
        config.n_agents <= 2
        or _ties(_radii(config), scale)
        or _coincident(config.positions, scale).any()
        or _rank(config.positions, scale) <= 1
    )
    assert degenerate and 2 <= config.n_agents <= 12
    assert np.abs(config.positions).max() <= 5.0
    assert np.linalg.norm(config.velocities, axis=1).max() <= 1.5 * (1 + 1e-12)


@pytest.mark.parametrize("shape", fst.TIED_SHAPES)
@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_each_tied_shape_is_what_it_says(shape, data):
    config = data.draw(fst.tied_configurations(shapes=(shape,), max_agents=12, max_coordinate=20.0))
    positions, n, d = config.positions, config.n_agents, config.dims
    radii = _radii(config)
    scale = np.abs(positions).max() + 1.0
    tol = 1e-9 * scale
    if shape == "polygon":
        assert n >= 3 and np.ptp(radii) <= tol and _rank(positions, scale) == 2
    elif shape == "hub":
        order = np.argsort(radii)
        assert n >= 4 and radii[order[0]] <= tol and np.ptp(radii[order[1:]]) <= tol
    elif shape == "grid":
        side = round(n ** (1 / d))
        assert side >= 2 and side**d == n and _rank(positions, scale) == d
    elif shape == "spot":
        assert n >= 2 and np.ptp(positions, axis=0).max() <= tol
    elif shape == "pairs":
        assert n >= 2 and _coincident(positions, scale).all()
    elif shape == "one":
        assert n == 1
    elif shape == "line":
        centered = positions - positions.mean(axis=0)
        direction = np.linalg.svd(centered)[2][0]
        steps = np.diff(np.sort(centered @ direction))
        assert n >= 2 and _rank(positions, scale) == 1 and np.ptp(steps) <= tol
    else:
        assert n >= 2 and _rank(positions, scale) <= 1


@settings(max_examples=30, deadline=None)
@given(fst.configurations(min_agents=3, max_agents=5, dims=2, max_coordinate=4.0, max_speed=0.5, degenerate=True))
def test_configurations_may_be_degenerate_within_their_bounds(config):
    assert 3 <= config.n_agents <= 5 and config.dims == 2
    assert np.abs(config.positions).max() <= 4.0 and np.abs(config.velocities).max() <= 0.5


@settings(max_examples=10, deadline=None)
@given(st.data())
def test_configuration_lists_and_index_pairs_are_what_metrics_take(data):
    configs = data.draw(fst.configuration_lists(min_size=2, max_size=4, max_agents=4))
    assert 2 <= len(configs) <= 4 and len({(c.n_agents, c.dims) for c in configs}) == 1
    pairs = data.draw(fst.index_pairs(len(configs)))
    assert pairs.ndim == 2 and pairs.shape[1] == 2 and len({tuple(p) for p in pairs.tolist()}) == len(pairs)
    assert np.all(pairs[:, 0] < pairs[:, 1]) and pairs.min() >= 0 and pairs.max() < len(configs)
    distances = flockkit.get("metric", "icp-hungarian").pairwise(configs, pairs)
    assert distances.shape == (len(pairs),) and np.all(np.isfinite(distances)) and np.all(distances >= 0)


# -- skeletal animation: what controllers return and are asked ----------------------------------


@settings(max_examples=30, deadline=None)
@given(fst.skeletal_clips())
def test_skeletal_clips_are_valid(clip):
    parents = clip.skeleton.parents
    assert all(p < j for j, p in enumerate(parents)) and parents[0] == -1
    assert np.allclose(np.linalg.norm(clip.rotations, axis=-1), 1.0)
    assert clip.translations.shape == (clip.n_frames, clip.skeleton.n_joints, 3)
    assert all(0 <= e.time <= clip.duration for e in clip.events)


@settings(max_examples=40, deadline=None)
@given(fst.skeletal_clips(keys=["channels"]), st.lists(st.floats(-0.5, 3.0), min_size=1, max_size=6))
def test_channel_clips_sample_as_the_gltf_spec_defines(clip, times):
    """Every joint a drawn channel moves is, at any time, what an evaluation written from glTF 2.0
    Appendix C alone (tests/core/animation_spec.py) gives; the others keep their rest pose."""
    from tests.core.animation_spec import channel_value

    pose = clip.sample(times)
    moved = {}
    for channel in clip.channels:
        joint = channel.joint if isinstance(channel.joint, int) else clip.skeleton.names.index(channel.joint)
        moved[joint, channel.path] = {
            "times": channel.times, "values": channel.values, "path": channel.path,
            "interpolation": channel.interpolation, "in_tangents": channel.in_tangents,
            "out_tangents": channel.out_tangents,
        }  # fmt: skip
    rest = clip.skeleton.rest
    for k, t in enumerate(times):
        for j in range(clip.skeleton.n_joints):
            played = (
                ("rotation", pose.rotations, rest.rotations),
                ("translation", pose.translations, rest.translations),
            )
            for path, got, still in played:
                want = channel_value(moved[j, path], t) if (j, path) in moved else still[j]
                if path == "rotation":
                    want = want / np.linalg.norm(want)
                    assert min(np.abs(got[k, j] - want).max(), np.abs(got[k, j] + want).max()) < 1e-9
                else:
                    assert np.abs(got[k, j] - want).max() < 1e-9 * (1 + np.abs(want).max())


@settings(max_examples=30, deadline=None)
@given(fst.skeletons(min_joints=2, max_joints=10))
def test_skeletons_are_trees(skeleton):
    """Following parents from any joint reaches a root, in as many steps as its depth."""
    assert 2 <= skeleton.n_joints <= 10 and len(set(skeleton.names)) == skeleton.n_joints
    for joint in range(skeleton.n_joints):
        steps, at = 0, joint
        while skeleton.parents[at] >= 0:
            assert skeleton.parents[at] < at
            at, steps = int(skeleton.parents[at]), steps + 1
        assert steps == skeleton.depth[joint]


@settings(max_examples=30, deadline=None)
@given(fst.poses(batch=(3,)))
def test_poses_have_the_batch_shape(pose):
    assert pose.shape == (3,) and np.allclose(np.linalg.norm(pose.rotations, axis=-1), 1.0)


@settings(max_examples=30, deadline=None)
@given(fst.pose_times(min_size=0, max_size=6, max_time=3.0))
def test_pose_times_are_what_pose_accepts(times):
    assert times.ndim == 1 and len(times) <= 6 and np.all((times >= 0) & (times <= 3.0))
    assert np.array_equal(stream_times(times, owner="test"), times)


@settings(max_examples=30, deadline=None)
@given(fst.time_windows(max_windows=3, max_time=2.0))
def test_time_windows_follow_one_another(windows):
    assert 1 <= len(windows) <= 3 and windows[0][0] >= 0 and windows[-1][1] <= 2.0
    assert all(start <= stop for start, stop in windows)
    assert all(a[1] == b[0] for a, b in zip(windows[:-1], windows[1:]))


# -- graphs, walks and what walks with targets take ---------------------------------------------


@settings(max_examples=15, deadline=None)
@given(st.data())
def test_walks_fit_their_graph_and_play(data):
    graph = data.draw(fst.motion_graphs())
    walk = data.draw(fst.walks(graph, max_translation=3.0))
    motion = synthesize_graph(graph, walk)
    assert motion.n_agents == graph.motion.n_agents and np.isfinite(motion.positions).all()
    rotation, translation = walk.pose(graph.motion.dims)
    assert _proper(rotation) and np.abs(translation).max() <= 3.0


@settings(max_examples=15, deadline=None)
@given(fst.layered_walks(dims=3, max_parts=2))
def test_layered_walks_deal_every_point_to_one_part_and_play(drawn):
    layers, walk = drawn
    assert 1 <= layers.n_parts <= 2 and len(walk.walks) == layers.n_parts and layers.source.dims == 3
    parts = layers.segmentation.parts()
    assert sorted(np.concatenate(parts).tolist()) == list(range(layers.source.n_agents))
    for points, graph in zip(parts, layers.graphs):
        np.testing.assert_array_equal(layers.source.positions[:, points], graph.motion.positions)
    assert np.isfinite(flockkit.synthesize(layers, walk).positions).all()


@settings(max_examples=30, deadline=None)
@given(fst.features(min_frames=2, max_frames=8, dims=3, dt=0.1))
def test_features_are_normalized_arrows(features):
    assert isinstance(features, Features) and 2 <= features.n_frames <= 8 and features.dt == 0.1
    assert features.vectors.shape[1] == 3 and features.lengths.max() <= 1 + 1e-12


@settings(max_examples=30, deadline=None)
@given(fst.keyframed_arrows(duration=4.0, max_keyframes=4))
def test_keyframed_arrows_are_what_targets_take(keyframes):
    times, vectors = arrow_keyframes(keyframes, "target", duration=4.0)
    assert 1 <= len(times) <= 4 and np.all(np.diff(times) > 0) and np.linalg.norm(vectors, axis=1).max() <= 1 + 1e-12
    assert Features.from_keyframes(keyframes, n_frames=41, dt=0.1).n_frames == 41


# -- segmentations and meshes ----------------------------------------------------------------------


@settings(max_examples=40, deadline=None)
@given(fst.segmentations(max_points=12, max_parts=4))
def test_segmentations_use_every_part(segmentation):
    assert segmentation.n_parts <= 4 and set(segmentation.labels) == set(range(segmentation.n_parts))


@settings(max_examples=20, deadline=None)
@given(fst.animated_meshes(max_vertices=6, max_faces=4))
def test_animated_meshes_index_their_vertices(mesh):
    faces = mesh.faces
    assert mesh.motion.dims == 3 and 3 <= mesh.motion.n_agents <= 6 and 1 <= len(faces) <= 4
    assert faces.shape[1] in (3, 4) and faces.min() >= 0 and faces.max() < mesh.motion.n_agents
    assert all(len(set(face)) == len(face) for face in faces.tolist())


# -- constrained problems and behaviors' optional inputs ------------------------------------------


@settings(max_examples=10, deadline=None)
@given(st.data())
def test_problems_and_proposal_contexts(data):
    behavior = flockkit.get("behavior", "boids", dt=0.1)
    context, motion = data.draw(fst.proposal_contexts(behavior, max_agents=4))
    problem = context.problem
    assert motion.positions.shape == (problem.n_frames, problem.n_agents, problem.dims)
    assert context.pinned.shape == (problem.n_frames, problem.n_agents) and context.pinned.any()
    proposal = data.draw(fst.proposals())
    assert 0 <= proposal.start < proposal.stop <= proposal.motion.n_frames and proposal.agents


@settings(max_examples=30, deadline=None)
@given(st.data())
def test_frame_windows_slice_like_a_full_evaluation(data):
    motion = data.draw(fst.motions(min_frames=2, max_frames=8, max_agents=3))
    start, stop = data.draw(fst.frame_windows(motion.n_frames))
    assert 0 <= start <= (motion.n_frames if stop is None else stop) <= motion.n_frames
    behavior = flockkit.get("behavior", "boids", dt=motion.dt)
    full = behavior.log_plausibility(motion)
    assert np.allclose(behavior.log_plausibility(motion, start, stop), full[start:stop])


@settings(max_examples=10, deadline=None)
@given(st.data())
def test_guides_and_group_guides_are_what_a_guided_behavior_takes(data):
    n, steps, d = 5, 3, data.draw(st.sampled_from([2, 3]))
    guide = data.draw(fst.guides(n_agents=n, steps=steps, dims=d, max_guided=2))
    assert 1 <= len(guide) <= 2 and all(0 <= a < n and path.shape == (steps + 1, d) for a, path in guide.items())
    groups = data.draw(fst.group_guides(n_agents=n, steps=steps, dims=d))
    members = [a for agents, _ in groups for a in agents]
    assert len(members) == len(set(members)) and all(path.shape == (steps + 1, d) for _, path in groups)
    behavior = flockkit.get("behavior", "boids", dt=0.1)
    initial = flockkit.State(positions=np.arange(n * d, dtype=float).reshape(n, d), velocities=np.ones((n, d)))
    rng = np.random.default_rng(0)
    guided = behavior.forward(initial, steps, rng, guide=guide, group_guide=groups)
    for agent, path in guide.items():
        assert np.allclose(guided.positions[1:, agent], path[1:])


@settings(max_examples=30, deadline=None)
@given(fst.regions(max_coordinate=5.0, max_size=2.0))
def test_regions_are_valid_and_hold_their_centre(region):
    inside = region.interior_point()
    assert region.dims in (2, 3) and region.contains(inside)
    lower, upper = region.bounds()
    assert np.all(lower < upper) and np.all(np.abs(region.centroid()) <= 5.0 + 2.0)


@pytest.mark.parametrize("kind", sorted(KINDS))
@settings(max_examples=15, deadline=None)
@given(data=st.data())
def test_capabilities_declare_only_what_the_kind_reads(kind, data):
    declared = data.draw(fst.declared_capabilities(kind=kind)).declared()
    assert set(declared) - {"dims"} <= KINDS[kind].fields
    assert not declared.get("coupling") or declared.get("residuals")


# -- bad arguments fail when the strategy is made ----------------------------------------------


@pytest.mark.parametrize(
    "factory, kwargs",
    [
        (fst.alignments, {"n_agents": 0}),
        (fst.symmetric_configurations, {"max_agents": 3}),
        (fst.poses, {"batch": (0,)}),
        (fst.skeletons, {"min_joints": 3, "max_joints": 2}),
        (fst.events, {"names": ()}),
        (fst.skeletal_clips, {"fps": 0}),
        (fst.skeletal_clips, {"min_frames": 0}),
        (fst.skeletal_clips, {"keys": ["bones"]}),
        (fst.channels, {"skeleton": "not a skeleton"}),
        (fst.channels, {"skeleton": inputs.walker().skeleton, "interpolations": ["CUBIC"]}),
        (fst.segmentations, {"max_parts": 0}),
        (fst.animated_meshes, {"max_vertices": 2}),
        (fst.animated_meshes, {"max_faces": 0}),
        (fst.motion_graphs, {"max_agents": 1}),
        (fst.walks, {"graph": "not a graph"}),
        (fst.layered_walks, {"max_parts": 0}),
        (fst.layered_walks, {"max_agents": 1}),
        (fst.layered_walks, {"dims": 4}),
        (fst.problems, {"max_constraints": 0}),
        (fst.proposal_contexts, {"behavior": 3}),
        (fst.configurations, {"degenerate": "yes"}),
        (fst.tied_configurations, {"shapes": ("blob",)}),
        (fst.tied_configurations, {"shapes": "polygon"}),
        (fst.tied_configurations, {"shapes": ()}),
        (fst.tied_configurations, {"shapes": ("grid",), "min_agents": 5, "max_agents": 7, "dims": 2}),
        (fst.tied_configurations, {"max_radius": 20.0, "max_coordinate": 10.0}),
        (fst.tied_configurations, {"min_agents": 4, "max_agents": 3}),
        (fst.tied_configurations, {"max_speed": 0}),
        (fst.tied_configurations, {"dims": 4}),
        (fst.features, {"min_frames": 0}),
        (fst.features, {"dt": -1.0}),
        (fst.features, {"dims": 1}),
        (fst.keyframed_arrows, {"duration": 0}),
        (fst.keyframed_arrows, {"max_keyframes": 0}),
        (fst.pose_times, {"min_size": 3, "max_size": 2}),
        (fst.pose_times, {"max_time": float("inf")}),
        (fst.time_windows, {"max_windows": 0}),
        (fst.frame_windows, {"n_frames": 0}),
        (fst.configuration_lists, {"min_size": 0}),
        (fst.configuration_lists, {"min_agents": 3, "max_agents": 2}),
        (fst.index_pairs, {"n_items": 1}),
        (fst.index_pairs, {"n_items": 3, "max_pairs": 0}),
        (fst.guides, {"n_agents": 3, "steps": 2, "dims": None}),
        (fst.guides, {"n_agents": 3, "steps": -1, "dims": 2}),
        (fst.group_guides, {"n_agents": 0, "steps": 2, "dims": 2}),
        (fst.group_guides, {"n_agents": 3, "steps": 2, "dims": 2, "max_groups": 0}),
        (fst.regions, {"kinds": ("cone",)}),
        (fst.regions, {"kinds": ("polygon",), "dims": 3}),
        (fst.regions, {"max_size": 0}),
        (fst.declared_capabilities, {"kind": "nope"}),
    ],
)
def test_new_strategies_reject_bad_arguments_eagerly(factory, kwargs):
    with pytest.raises(InvalidArgument):
        factory(**kwargs)


def test_walks_reject_a_bad_translation_bound_eagerly():
    with pytest.raises(InvalidArgument):
        fst.walks(inputs.graph(), max_translation=0)
