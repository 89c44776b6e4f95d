"""Validation of episode requests, shared by the StartEpisode service and ``qgl episode start``."""
from __future__ import annotations

from dataclasses import dataclass

from qg_common.types import N_START_POSES as N_POSES

__all__ = ["EpisodeRequest", "MODES", "REWARDS", "N_POSES"]

MODES = ("train", "test")
REWARDS = ("sparse", "dense")


@dataclass(frozen=True)
class EpisodeRequest:
    """A validated request to run one episode.

    :param mode: ``train`` (exploration noise, long cap) or ``test`` (deterministic, short cap).
    :param initial_pose: -1 for the next pose of the fixed rotation, else 0..7.
    :param seed: seed of this episode's exploration noise (0: derived from the episode count).
    :param reward: ``sparse`` or ``dense``; an empty string means the configured default.
    """
    mode: str
    initial_pose: int = -1
    seed: int = 0
    reward: str = ""

    def __post_init__(self) -> None:
        errors = []
        if self.mode not in MODES:
            errors.append(f"mode must be one of {'|'.join(MODES)}, got {self.mode!r}")
        if not -1 <= self.initial_pose < N_POSES:
            errors.append(f"initial_pose must be -1 (next in rotation) or 0..{N_POSES - 1}, "
                          f"got {self.initial_pose}")
        if self.reward not in REWARDS + ("",):
            errors.append(f"reward must be one of {'|'.join(REWARDS)} (or empty for the "
                          f"default), got {self.reward!r}")
        if not -2**31 <= self.seed < 2**31:
            errors.append(f"seed must fit in int32, got {self.seed}")
        if errors:
            raise ValueError("; ".join(errors))
