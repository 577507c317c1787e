"""Massive crowds (paper 003): skeletons and clips, shared streams of poses, the crowd runtime."""

from ..io.skin import SkinnedMesh, read_skin
from ..skeleton import (
    Channel,
    Event,
    Pose,
    RootMotion,
    SkeletalClip,
    Skeleton,
    carries_root_motion,
    extract_root_motion,
    sample_keys,
    stream_times,
)
from .drive import Cue, Driver, Gait, StateMachine
from .feet import driven_sliding, foot_sliding, ground_speed, plant_feet
from .pool import Stream, StreamPool, UniquePool, equation_4, equation_5
from .record import CrowdRecording, export_gltf, export_usd, record, write_engine_buffers
from .runtime import INSTANCE, Crowd, CrowdEvent, Hook, LookAt, PoseOverride
from .textures import (
    TEXTURE_INSTANCE,
    AnimationTextures,
    bake_textures,
    instance_buffer,
    instances,
    shader_source,
    skin,
    skinning_matrices,
)

__all__ = [
    "SkeletalClip",
    "Channel",
    "sample_keys",
    "Event",
    "Pose",
    "Skeleton",
    "stream_times",
    "RootMotion",
    "extract_root_motion",
    "carries_root_motion",
    "Stream",
    "StreamPool",
    "UniquePool",
    "equation_4",
    "equation_5",
    "Crowd",
    "CrowdEvent",
    "Hook",
    "LookAt",
    "PoseOverride",
    "INSTANCE",
    "Gait",
    "StateMachine",
    "Cue",
    "CrowdRecording",
    "record",
    "export_usd",
    "export_gltf",
    "write_engine_buffers",
    "Driver",
    "ground_speed",
    "foot_sliding",
    "driven_sliding",
    "plant_feet",
    "AnimationTextures",
    "bake_textures",
    "instance_buffer",
    "instances",
    "skin",
    "skinning_matrices",
    "shader_source",
    "TEXTURE_INSTANCE",
    "SkinnedMesh",
    "read_skin",
]
