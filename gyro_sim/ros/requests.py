"""Requests to the physics loop from the executor thread (the ~/reset and ~/pause services),
typed, and the mailbox that carries them: posted by one thread, served by the physics thread
between two chunks of steps, each answered with one line."""
from __future__ import annotations

import collections
import threading
from dataclasses import dataclass, field
from typing import Callable, ClassVar, Union


@dataclass(frozen=True)
class Reset:
    """Back to the scene's initial state; node time keeps increasing."""

    name: ClassVar[str] = "reset"


@dataclass(frozen=True)
class Pause:
    """Pause (``paused`` True) or resume (False) the simulation."""

    paused: bool
    name: ClassVar[str] = "pause"


Request = Union[Reset, Pause]


@dataclass
class Pending:
    """A request posted and not yet answered: `done` is set once `message` holds the answer."""

    request: Request
    done: threading.Event = field(default_factory=threading.Event)
    message: str = ""


class Mailbox:
    """Requests in the order posted; any thread posts, the physics thread serves."""

    def __init__(self):
        self._queue: collections.deque[Pending] = collections.deque()

    def post(self, request: Request) -> Pending:
        """Queue `request` and return at once (its answer comes in the returned `Pending`)."""
        pending = Pending(request)
        self._queue.append(pending)
        return pending

    def ask(self, request: Request, timeout: float) -> tuple[bool, str]:
        """Queue `request` and wait for its answer: (True, answer), or (False, why) after `timeout` s."""
        pending = self.post(request)
        if not pending.done.wait(timeout):
            return False, f"{request.name}: the physics loop did not answer within {timeout} s"
        return True, pending.message

    def serve(self, handle: Callable[[Request], str]) -> None:
        """Answer every request waiting with `handle(request)`, in the order posted."""
        while self._queue:
            pending = self._queue.popleft()
            pending.message = handle(pending.request)
            pending.done.set()
