"""Data-driven groups (paper 000): motion graphs of recorded group motion, walks through them
(one graph, or the graphs of an object's parts), and synthesis of new motion from walks."""

from .bridges import BRIDGE_PLAUSIBILITY, bridge, bridge_plan
from .graph import (
    Clip,
    MotionGraph,
    Transition,
    Walk,
    local_minima,
    local_minima_of_cells,
    loop_period,
    phase_shifts,
    turns,
)
from .synthesis import blended_frames, played_frames, played_length, played_positions, synthesize_graph, synthesize_many
from .walking import part_seeds, walk_graph, walk_parts

__all__ = [
    "MotionGraph",
    "Clip",
    "Transition",
    "Walk",
    "turns",
    "loop_period",
    "phase_shifts",
    "local_minima",
    "local_minima_of_cells",
    "walk_graph",
    "walk_parts",
    "part_seeds",
    "synthesize_graph",
    "synthesize_many",
    "played_positions",
    "played_length",
    "played_frames",
    "blended_frames",
    "bridge",
    "bridge_plan",
    "BRIDGE_PLAUSIBILITY",
]
