"""The nodes' thread-pool executor keeps up with a 1 kHz topic without a busy loop.

rclpy's own ``MultiThreadedExecutor`` (Jazzy 7.1) resubmits a callback that waits in its pool
in a loop that holds a core and the GIL (``qg_common/callback_executor.py``). On this test's
1 kHz topic it spent 1.8 of 2 s of CPU in its spinning thread and took 177 of ~1800 messages.

The subject is the executor's throughput, not the kernel's scheduling: the subscription keeps a
second of messages (a history of 10 forgives only 10 ms unscheduled, and a loaded 2-core CI
machine took 784 of 1017 with it), and what is still queued when publishing stops is drained.
"""
from __future__ import annotations

import threading
import time

import pytest

pytestmark = pytest.mark.ros

HISTORY = 1000          # a second of the 1 kHz topic


def test_a_1khz_topic_is_taken_whole_without_a_busy_spinning_thread() -> None:
    import rclpy
    from qg_common.callback_executor import CallbackThreadPool
    from rclpy.node import Node
    from std_msgs.msg import Header

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=231)      # no test's processes use it
    node = Node("callback_pool_test", context=context)
    taken = []
    node.create_subscription(Header, "ticks", taken.append, HISTORY)
    publisher = node.create_publisher(Header, "ticks", HISTORY)
    stop, published = threading.Event(), []

    def publish() -> None:
        while not stop.is_set():
            publisher.publish(Header())
            published.append(1)
            time.sleep(0.001)

    executor = CallbackThreadPool(num_threads=2, context=context)
    executor.add_node(node)
    thread = threading.Thread(target=publish)
    thread.start()
    try:
        cpu0, end = time.thread_time(), time.monotonic() + 2.0
        while time.monotonic() < end:
            executor.spin_once(timeout_sec=0.1)
        spin_cpu = time.thread_time() - cpu0
        stop.set()
        thread.join()
        drained = time.monotonic() + 0.5        # rclpy's busy executor takes ~45 in this time
        while time.monotonic() < drained and len(taken) < len(published):
            executor.spin_once(timeout_sec=0.05)
    finally:
        stop.set()
        thread.join()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    print(f"spinning thread: {spin_cpu:.2f} s of CPU in 2 s; {len(taken)} of {len(published)} "
          f"messages taken")
    assert spin_cpu < 0.8
    assert len(taken) >= 0.8 * len(published)
