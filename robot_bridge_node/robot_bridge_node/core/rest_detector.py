"""When an RL step is over: the tool has come to rest, or the step took too long.

The residual policy applies a wrench and waits for the arm to settle, so the step length is set
by the physics, not a clock. "At rest" means both speeds stayed below their thresholds for a hold
time; a minimum duration keeps the detector from firing before the arm has reacted at all and a
maximum ends steps that keep creeping.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from qg_common.params import config_from_dict

__all__ = ["RestConfig", "RestDetector"]


@dataclass(frozen=True)
class RestConfig:
    """Thresholds of the step-completion logic (SPEC section 1)."""
    linear_threshold: float = 0.002    # [m/s]
    angular_threshold: float = 0.02    # [rad/s]
    hold_time: float = 0.02            # [s] both speeds below threshold this long
    min_time: float = 0.02             # [s]
    max_time: float = 3.0              # [s] a safety bound: the step ends at rest (docs/learning.md 3)

    def __post_init__(self) -> None:
        for name in ("linear_threshold", "angular_threshold", "max_time"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.hold_time <= self.max_time:
            raise ValueError(f"hold_time must be in [0, max_time], got {self.hold_time}")
        if not 0.0 <= self.min_time <= self.max_time:
            raise ValueError(f"min_time must be in [0, max_time], got {self.min_time}")

    @classmethod
    def from_dict(cls, params: dict[str, Any]) -> RestConfig:
        """From the ``rest`` section of ``config/bridge.yaml``."""
        return config_from_dict(cls, params)


class RestDetector:
    """Fed the tool speeds every tick; says when the current step is complete."""

    def __init__(self, config: RestConfig | None = None) -> None:
        self.config = config or RestConfig()
        self.reset()

    def reset(self) -> None:
        """A new step starts now."""
        self.elapsed = 0.0
        self.quiet = 0.0
        self.at_rest = False
        self.timed_out = False

    def update(self, linear_speed: float, angular_speed: float, dt: float) -> bool:
        """Account for one tick of ``dt`` seconds; True once the step is complete.

        :returns: ``at_rest or timed_out``; both flags stay set until ``reset``.
        """
        c = self.config
        self.elapsed += dt
        still = linear_speed < c.linear_threshold and angular_speed < c.angular_threshold
        self.quiet = self.quiet + dt if still else 0.0
        eps = 1e-9  # elapsed is a float sum of ticks
        if self.quiet >= c.hold_time - eps and self.elapsed >= c.min_time - eps:
            self.at_rest = True
        elif self.elapsed >= c.max_time - eps and not self.at_rest:
            self.timed_out = True
        return self.at_rest or self.timed_out
