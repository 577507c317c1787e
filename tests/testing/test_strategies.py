"""Every value type a kind receives or returns has a strategy, and each draws valid values."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.errors import InvalidArgument

import flockkit
from flockkit.graphs import synthesize_graph
from flockkit.kinds import KINDS
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
    "Pose": "poses",
    "Event": "events",
    "Skeleton": "skeletons",
}


@pytest.mark.parametrize("path", sorted({p for k in KINDS.values() for p in (*k.receives, *k.returns)}))
def test_every_value_a_kind_handles_has_a_strategy(path):
    assert DRAWN_BY[path.rpartition(".")[2]] in fst.__all__


@settings(max_examples=30, deadline=None)
@given(fst.alignments())
def test_alignments_are_proper(alignment):
    d = alignment.rotation.shape[0]
    assert np.allclose(alignment.rotation @ alignment.rotation.T, np.eye(d)) and np.isclose(
        np.linalg.det(alignment.rotation), 1.0
    )
    assert sorted(alignment.assignment) == list(range(len(alignment.assignment))) and alignment.distance >= 0


@settings(max_examples=40, deadline=None)
@given(fst.symmetric_configurations())
def test_degenerate_configurations_tie(config):
    radii = np.linalg.norm(config.positions - config.center_of_mass(), axis=1)
    ties = len(np.unique(np.round(radii / max(radii.max(), 1e-12), 6))) < config.n_agents
    assert config.n_agents == 1 or ties or config.n_agents == 2


@settings(max_examples=30, deadline=None)
@given(fst.skeletal_clips())
def test_skeletal_clips_are_valid(clip):
    parents = clip.skeleton.parents
    assert all(p < j for j, p in enumerate(parents)) and parents[0] == -1
    assert np.allclose(np.linalg.norm(clip.rotations, axis=-1), 1.0)
    assert all(0 <= e.time <= clip.duration for e in clip.events)


@settings(max_examples=30, deadline=None)
@given(fst.poses(batch=(3,)))
def test_poses_have_the_batch_shape(pose):
    assert pose.shape == (3,) and np.allclose(np.linalg.norm(pose.rotations, axis=-1), 1.0)


@settings(max_examples=40, deadline=None)
@given(fst.segmentations(max_points=12, max_parts=4))
def test_segmentations_use_every_part(segmentation):
    assert segmentation.n_parts <= 4 and set(segmentation.labels) == set(range(segmentation.n_parts))


@settings(max_examples=20, deadline=None)
@given(fst.animated_meshes())
def test_animated_meshes_index_their_vertices(mesh):
    assert mesh.faces.max() < mesh.motion.n_agents and mesh.motion.dims == 3


@settings(max_examples=15, deadline=None)
@given(st.data())
def test_walks_fit_their_graph_and_play(data):
    graph = data.draw(fst.motion_graphs())
    walk = data.draw(fst.walks(graph))
    motion = synthesize_graph(graph, walk)
    assert motion.n_agents == graph.motion.n_agents and np.isfinite(motion.positions).all()


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


@pytest.mark.parametrize(
    "factory, kwargs",
    [
        (fst.alignments, {"n_agents": 0}),
        (fst.symmetric_configurations, {"max_agents": 3}),
        (fst.poses, {"batch": (0,)}),
        (fst.skeletons, {"min_joints": 3, "max_joints": 2}),
        (fst.events, {"names": ()}),
        (fst.skeletal_clips, {"fps": 0}),
        (fst.segmentations, {"max_parts": 0}),
        (fst.animated_meshes, {"max_vertices": 2}),
        (fst.motion_graphs, {"max_agents": 1}),
        (fst.walks, {"graph": "not a graph"}),
        (fst.problems, {"max_constraints": 0}),
        (fst.proposal_contexts, {"behavior": 3}),
    ],
)
def test_new_strategies_reject_bad_arguments_eagerly(factory, kwargs):
    with pytest.raises(InvalidArgument):
        factory(**kwargs)
