"""The typed requests to the physics loop and their mailbox (no thread, no ROS)."""
from __future__ import annotations

import threading

from gyro_sim.ros.requests import Mailbox, Pause, Reset


def test_requests_are_answered_in_the_order_posted():
    box = Mailbox()
    first, second = box.post(Reset()), box.post(Pause(True))
    seen = []
    box.serve(lambda req: seen.append(req) or f"answer {len(seen)}")
    assert seen == [Reset(), Pause(True)]
    assert first.done.is_set() and first.message == "answer 1"
    assert second.done.is_set() and second.message == "answer 2"
    box.serve(lambda req: seen.append(req))  # nothing left: the handler is not called
    assert len(seen) == 2


def test_a_request_nobody_serves_says_so_by_name():
    ok, why = Mailbox().ask(Pause(False), timeout=0.0)
    assert not ok and why == "pause: the physics loop did not answer within 0.0 s"
    ok, why = Mailbox().ask(Reset(), timeout=0.0)
    assert not ok and why.startswith("reset: ")


def test_ask_waits_for_the_answer_of_the_serving_thread():
    box = Mailbox()
    posted = threading.Event()
    real_post = box.post
    box.post = lambda req: (real_post(req), posted.set())[0]

    def serve():
        posted.wait(10)
        box.serve(lambda req: f"paused={req.paused}")

    server = threading.Thread(target=serve)
    server.start()
    assert box.ask(Pause(True), timeout=10.0) == (True, "paused=True")
    server.join(10)
