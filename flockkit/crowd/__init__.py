"""Massive crowds (paper 003): skeletons and clips, controllers' streams, the crowd runtime."""

from .skeleton import Event, Pose, SkeletalClip, Skeleton, read_clips, stream_times

__all__ = ["SkeletalClip", "Event", "Pose", "Skeleton", "read_clips", "stream_times"]
