"""Whether the learner reads our transitions: the ROS graph, grouped by process.

A reliable publisher delivers nothing to a reader it has not matched, so an episode's first
transitions are lost to a learner whose reader the executor has not yet discovered. Counting
the readers in the graph is not enough after a learner restart: the dead learner's reader stays
in the graph, matched, until its participant's lease runs out (seconds), while the new one may
not be there yet. The endpoints of one process share their DDS participant, named by the first
12 bytes of each endpoint's 16-byte GID (the GUID prefix; Fast DDS and Cyclone DDS alike), and
the new learner's heartbeat writer is in the graph once its heartbeat has been heard. So the
question becomes: does every process that publishes learner heartbeats also have a reader of
the transitions in the graph, and has the publisher matched every reader there is?

Node names are not used: a process's node names reach the graph later than its endpoints
(until then they read ``_NODE_NAME_UNKNOWN_``).
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any

__all__ = ["PARTICIPANT_PREFIX", "participant", "learner_reads_transitions"]

#: Bytes of an endpoint's GID that name its DDS participant (its process, under ROS 2).
PARTICIPANT_PREFIX = 12


def participant(endpoint: Any) -> bytes:
    """The DDS participant (the process) of a graph endpoint (``TopicEndpointInfo``)."""
    return bytes(endpoint.endpoint_gid[:PARTICIPANT_PREFIX])


def learner_reads_transitions(readers: Iterable[Any], heartbeat_writers: Iterable[Any],
                              matched: int) -> bool:
    """Whether the transitions reach every learner in the graph.

    :param readers: the graph's readers of the transitions topic (any node's).
    :param heartbeat_writers: the graph's writers of the learner's heartbeat (diagnostics).
    :param matched: the readers the transitions publisher has matched.
    :returns: True when there is a learner, each learner process has a transitions reader in
        the graph, and the publisher has matched all the readers in the graph.
    """
    readers = list(readers)
    learners = {participant(w) for w in heartbeat_writers}
    reading = {participant(r) for r in readers}
    return bool(learners) and learners <= reading and matched >= len(readers)
