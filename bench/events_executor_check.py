"""Reproduction: rclpy.experimental.EventsExecutor delivers no subscription callback (not a test).

``python bench/events_executor_check.py`` subscribes ``/evt`` with the EventsExecutor for 6 s and
prints how many messages arrived; publish to ``/evt`` meanwhile (e.g. a SingleThreadedExecutor
node, 30 std_msgs/String at 20 Hz). With the PyPI wheels here (rclpy 7.1.6, rmw_fastrtps_cpp
8.4.3) it prints ``total 0``; the same node under SingleThreadedExecutor receives all 30.

Why (gdb on the spinning process, and rclpy's events_executor/events_queue.cpp): ``spin()``
without a timeout runs ``RunUntil(steady_clock::time_point::max())``, a
``condition_variable::wait_until`` on that deadline. These wheels' ``std::condition_variable``
keeps time on the system clock (no ``pthread_cond_clockwait`` in the glibc they were built for),
so the deadline is converted to the system clock and overflows into the past: the wait returns at
once, forever. The spinning thread busy-loops (``steady_clock::now``/``system_clock::now``)
holding the queue's mutex, and the threads that enqueue the events (the middleware's listener for
messages, the timers thread) block on that mutex: no subscription or timer callback runs.
``spin_once(timeout_sec=...)`` has a finite deadline and works. A second fault: a callback that
takes ``MessageInfo`` is called with the ``(msg, info)`` tuple as one argument (a TypeError,
shown as "SystemError: null argument to internal routine"). Both are worked around by
:class:`switchobs_ros.executor.PolledEventsExecutor` (``SWITCHOBS_EXECUTOR=events``).
"""

from __future__ import annotations

import os
import threading
import time

import rclpy
from rclpy.experimental import EventsExecutor
from std_msgs.msg import String


def main() -> None:
    rclpy.init()
    node = rclpy.create_node("evsub")
    got: list[int] = []
    node.create_subscription(String, "/evt", lambda m: got.append(1), 10)
    ex = EventsExecutor()
    ex.add_node(node)

    def stop() -> None:
        time.sleep(6)
        print("total", len(got), flush=True)
        os._exit(0)

    threading.Thread(target=stop, daemon=True).start()
    ex.spin()


if __name__ == "__main__":
    main()
