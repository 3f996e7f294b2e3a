"""The panel's worker: one thread that runs only the newest submitted parameters.

GUI callbacks run on a thread pool and can arrive concurrently while a slider is dragged;
``submit`` only records the newest item under a lock, and the worker coalesces: when newer
items arrive during a run, it runs once more with the newest only.

A typed number arrives one keystroke at a time ("0.3" as 0, 0., 0.3): ``submit(item,
settle_s=…)`` makes the worker wait until no newer item has come for ``settle_s`` seconds,
so a half-typed value is never run.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import Any


class Coalescer:
    """One worker thread that runs ``fn`` on the newest submitted item only.

    ``submit`` just stores the item (its submit time, and when it may run) under the lock and
    notifies. The worker takes the newest item once its settling time has passed with no newer
    one, runs ``fn`` outside the lock, then ``on_done(item, result, ms)`` with ``ms`` the time
    from that item's submission to the end of the run (the settling pause included), or
    ``on_error(item, exc)`` on any exception (the worker keeps going).
    """

    def __init__(
        self,
        fn: Callable[[Any], Any],
        on_done: Callable[[Any, Any, float], None] | None = None,
        on_error: Callable[[Any, BaseException], None] | None = None,
        name: str = "radarviz-tune-worker",
    ) -> None:
        self._fn = fn
        self._on_done = on_done
        self._on_error = on_error
        self._cond = threading.Condition()
        self._pending: tuple[Any, float, float] | None = None  # item, submitted, runs at
        self._busy = False
        self._stopping = False
        self.submitted = 0
        self.completed = 0  # runs finished, successful or not
        self.last_item: Any = None
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def submit(self, item: Any, settle_s: float = 0.0) -> None:
        """Make ``item`` the next to run, once ``settle_s`` seconds pass with no newer one."""
        now = time.perf_counter()
        with self._cond:
            self._pending = (item, now, now + max(settle_s, 0.0))
            self.submitted += 1
            self._cond.notify_all()

    def wait_idle(self, timeout: float | None = None) -> bool:
        """Wait until nothing is pending or running; False on timeout."""
        with self._cond:
            return self._cond.wait_for(
                lambda: (self._pending is None and not self._busy) or self._stopping, timeout
            )

    def stop(self, timeout: float = 10.0) -> None:
        with self._cond:
            self._stopping = True
            self._cond.notify_all()
        self._thread.join(timeout)

    @property
    def alive(self) -> bool:
        return self._thread.is_alive()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while True:
                    self._cond.wait_for(lambda: self._pending is not None or self._stopping)
                    if self._stopping:
                        return
                    assert self._pending is not None
                    wait = self._pending[2] - time.perf_counter()
                    if wait <= 0:
                        break
                    self._cond.wait(wait)  # a newer submit moves the time on
                item, t0, _ = self._pending
                self._pending = None
                self._busy = True
            try:
                try:
                    result = self._fn(item)
                except Exception as exc:  # never let a bad run stop the worker
                    if self._on_error is not None:
                        self._on_error(item, exc)
                else:
                    if self._on_done is not None:
                        self._on_done(item, result, (time.perf_counter() - t0) * 1e3)
            except Exception as exc:  # a failing callback must not stop the worker either
                print(f"radarviz tune: callback failed: {exc}", file=sys.stderr, flush=True)
            finally:
                with self._cond:
                    self._busy = False
                    self.completed += 1
                    self.last_item = item
                    self._cond.notify_all()
