"""The panel's worker: one thread that runs only the newest submitted parameters.

GUI callbacks run on a thread pool and can arrive concurrently while a slider is dragged;
``submit`` only records the newest item under a lock, and the worker coalesces: when newer
items arrive during a run, it runs once more with the newest only.

A typed number arrives one keystroke at a time ("0.3" as 0, 0., 0.3): ``submit(item,
settle_s=…)`` makes the worker wait until no newer item has come for ``settle_s`` seconds,
so a half-typed value is never run. A value the user has visibly finished (a slider let go,
Enter in a number box: ``hurry``) need not wait for the pause: its run goes out as soon as it
is ready.

A run may come in two stages, ``prepare`` then ``fn``: the worker prepares the newest item at
once (for the panel: simulate and log into a recording not yet sent) and runs ``fn`` on it
(send it to the viewer) only once the settling pause has passed with no newer item; a
prepared item overtaken by a newer one goes to ``discard`` instead and is never shown. So
the pause hides the simulation's time instead of adding to it.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from typing import Any


class _Failed:
    """A ``prepare`` that raised: its exception, reported once the item is due."""

    def __init__(self, exc: Exception) -> None:
        self.exc = exc


class Coalescer:
    """One worker thread that runs ``fn`` on the newest submitted item only.

    ``submit`` just stores the item (its submit time, and when it may run) under the lock and
    notifies. The worker prepares the newest item at once (``prepare``, the identity by
    default), waits until its settling time has passed with no newer one (a newer one: the
    prepared item goes to ``discard`` and the newer one is prepared), runs ``fn`` on the
    prepared item outside the lock, then ``on_done(item, result, ms)`` with ``ms`` the time
    from that item's submission to the end of the run (the settling pause included), or
    ``on_error(item, exc)`` on any exception of ``prepare`` or ``fn`` (the worker keeps going).
    """

    def __init__(
        self,
        fn: Callable[[Any], Any],
        on_done: Callable[[Any, Any, float], None] | None = None,
        on_error: Callable[[Any, BaseException], None] | None = None,
        name: str = "radarviz-tune-worker",
        prepare: Callable[[Any], Any] | None = None,
        discard: Callable[[Any], None] | None = None,
    ) -> None:
        self._fn = fn
        self._prepare = prepare
        self._discard = discard
        self._on_done = on_done
        self._on_error = on_error
        self._cond = threading.Condition()
        self._pending: tuple[Any, float, float] | None = None  # item, submitted, runs at
        self._hurry: tuple[Callable[[Any], bool], float] | None = None  # match, until
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
            runs_at = now + max(settle_s, 0.0)
            if self._hurry is not None and now <= self._hurry[1] and self._hurry[0](item):
                runs_at, self._hurry = now, None  # finished before its value arrived
            self._pending = (item, now, runs_at)
            self.submitted += 1
            self._cond.notify_all()

    def hurry(self, match: Callable[[Any], bool], expect_s: float = 0.0) -> bool:
        """End the settling pause of the pending item if ``match(item)``: the user has finished
        that value (let go of a slider, pressed Enter), so no later keystroke can change it.
        True if a pending item was hurried.

        The signal may overtake the value it is about (they come by different connections):
        with ``expect_s`` > 0 and nothing pending that matches, the next item submitted within
        ``expect_s`` seconds that matches runs without a pause.
        """
        now = time.perf_counter()
        with self._cond:
            if self._pending is not None and match(self._pending[0]):
                item, t0, runs_at = self._pending
                self._pending = (item, t0, min(runs_at, now))
                self._hurry = None
                self._cond.notify_all()
                return True
            self._hurry = (match, now + expect_s) if expect_s > 0 else None
            return False

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
                self._cond.wait_for(lambda: self._pending is not None or self._stopping)
                if self._stopping:
                    return
                assert self._pending is not None
                item, t0, _ = self._pending
                seq = self.submitted  # tells this item from a newer one
            prepared = self._prepared(item)
            with self._cond:
                while True:  # the settling pause: a newer submit moves the time on
                    if self._stopping or self.submitted != seq:
                        break
                    assert self._pending is not None
                    wait = self._pending[2] - time.perf_counter()
                    if wait <= 0:
                        break
                    self._cond.wait(wait)
                current = self.submitted == seq and not self._stopping
                if current:
                    self._pending = None
                    self._busy = True
            if not current:  # overtaken (or stopping): never shown
                self._drop(prepared)
                continue
            self._finish(item, t0, prepared)

    def _prepared(self, item: Any) -> Any:
        if self._prepare is None:
            return item
        try:
            return self._prepare(item)
        except Exception as exc:  # reported once the item is due, never if it is overtaken
            return _Failed(exc)

    def _drop(self, prepared: Any) -> None:
        if self._discard is None or isinstance(prepared, _Failed):
            return
        try:
            self._discard(prepared)
        except Exception as exc:
            print(f"radarviz tune: discard failed: {exc}", file=sys.stderr, flush=True)

    def _finish(self, item: Any, t0: float, prepared: Any) -> None:
        try:
            try:
                if isinstance(prepared, _Failed):
                    raise prepared.exc
                result = self._fn(prepared)
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
