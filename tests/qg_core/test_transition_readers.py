"""The executor's test of whether the learner reads its transitions, on graphs as a learner
restart leaves them: the dead learner's endpoints still listed and matched, the new one's
heartbeat writer heard before its transitions reader is discovered."""
from __future__ import annotations

from dataclasses import dataclass

from qg_learning_node.executor.transition_readers import learner_reads_transitions, participant


@dataclass(frozen=True)
class Endpoint:
    """What the executor reads of ``TopicEndpointInfo``."""
    node_name: str
    endpoint_gid: list[int]


def _gid(process: int, entity: int) -> list[int]:
    """A 16-byte GID: 12 bytes naming the process's participant, 4 naming the endpoint."""
    return [1, 15, process, 253, 114, 86, 54, 124, 0, 0, 0, 0, 0, 0, entity, 4]


OLD, NEW, RECORDER = 7, 9, 11


def test_the_participant_is_the_gids_first_twelve_bytes() -> None:
    reader, writer = Endpoint("learner", _gid(OLD, 36)), Endpoint("learner", _gid(OLD, 37))
    assert participant(reader) == participant(writer) == bytes(_gid(OLD, 0)[:12])
    assert participant(reader) != participant(Endpoint("learner", _gid(NEW, 36)))


def test_a_restarted_learner_is_waited_for_until_its_reader_is_discovered_and_matched() -> None:
    old_reader = Endpoint("learner", _gid(OLD, 36))
    old_beat, new_beat = Endpoint("learner", _gid(OLD, 37)), Endpoint("learner", _gid(NEW, 37))
    new_reader = Endpoint("_NODE_NAME_UNKNOWN_", _gid(NEW, 36))
    # Before the restart: one learner, its reader matched.
    assert learner_reads_transitions([old_reader], [old_beat], matched=1)
    # The new learner's heartbeat is heard, its reader not yet discovered: the dead one's
    # matched reader alone (what the node-name test let through) is not enough.
    assert not learner_reads_transitions([old_reader], [old_beat, new_beat], matched=1)
    # Discovered but not yet matched by the publisher.
    assert not learner_reads_transitions([old_reader, new_reader], [old_beat, new_beat],
                                         matched=1)
    # Matched: the episode may start (the dead endpoints leave the graph later, or not).
    assert learner_reads_transitions([old_reader, new_reader], [old_beat, new_beat], matched=2)
    assert learner_reads_transitions([new_reader], [new_beat], matched=1)


def test_no_learner_in_the_graph_or_an_unmatched_other_reader_is_not_a_reading_learner() -> None:
    reader, beat = Endpoint("learner", _gid(NEW, 36)), Endpoint("learner", _gid(NEW, 37))
    recorder = Endpoint("recorder", _gid(RECORDER, 36))
    assert not learner_reads_transitions([], [], matched=0)
    assert not learner_reads_transitions([recorder], [], matched=1)
    assert not learner_reads_transitions([reader, recorder], [beat], matched=1)
    assert learner_reads_transitions([reader, recorder], [beat], matched=2)
