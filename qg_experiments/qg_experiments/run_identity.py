"""What makes two experiment runs the same run: the test by which a sweep reuses a saved run
(``tasks.saved_result``) or an archived one (``run_archive``) and a run continues from saved
progress (``run_progress``).

A run is its spec's fields, the numbers of the config files it read (``config_digest``; where
they were read, config/ or a frozen copy for a long sweep, is not part of it) and the settings it
takes from elsewhere than its fields (``task_settings``: a standard task's settings of our
agents, the peg's networks). All three in JSON's terms, as a saved result holds them.
"""
from __future__ import annotations

import dataclasses
import json
from typing import Any

from qg_experiments.core.stack_settings import config_digest

__all__ = ["run_identity", "result_identity", "saved_identity", "is_run_of"]


def _fields(values: dict[str, Any]) -> dict[str, Any]:
    fields = json.loads(json.dumps(values))
    fields.pop("config_dir", None)
    return fields


def run_identity(spec: Any) -> dict[str, Any]:
    """The identity of the run ``spec`` describes, on this machine's config files."""
    return {"spec": _fields(dataclasses.asdict(spec)),
            "config_digest": config_digest(spec.config_dir),
            "task_settings": json.loads(json.dumps(getattr(spec, "task_settings", {})))}


def result_identity(result: dict[str, Any], defaults: dict[str, Any] | None = None
                    ) -> dict[str, Any]:
    """The identity a saved ``result`` holds, its spec's missing fields taken from
    ``defaults``; what is kept beside a run's episode rows (``episode_rows``)."""
    return {"spec": _fields({**(defaults or {}), **result.get("spec", {})}),
            "config_digest": result.get("config_digest"),
            "task_settings": result.get("task_settings", {})}


def saved_identity(result: dict[str, Any], spec: Any) -> dict[str, Any]:
    """The identity of a saved ``result`` of a run of ``spec``'s kind. A spec field added after
    the run was saved, at its default, leaves it the same run; a run saved before task settings
    existed had none."""
    return result_identity(result, {f.name: f.default for f in dataclasses.fields(spec)
                                    if f.default is not dataclasses.MISSING})


def is_run_of(result: dict[str, Any], spec: Any) -> bool:
    """Whether the saved ``result`` is of the run ``spec`` describes on this machine."""
    return saved_identity(result, spec) == run_identity(spec)
