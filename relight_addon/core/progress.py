"""How a long computation reports where it is, and where it stops when asked.

A computation runs inside ``reporting(callback)``: ``callback(fraction, message)`` is the
caller's (an operator's: it raises Cancelled once the user pressed Esc).  Stages say where they
are with ``report(fraction, message, until)``: the stage spans [fraction, until] of the whole;
``scope(lo, hi)`` maps the fractions of a sub-computation (a solve inside the precompute) into
[lo, hi] of its caller's.  Inner loops call ``tick(done)`` between chunks of work (``done`` the
part of the current stage done, when they know it): it passes a fraction within the stage to
the callback at most every TICK seconds, so the bar moves and a cancel is seen within a chunk,
not at the next stage.  Outside ``reporting`` every call is a no-op.

The reporter is per thread: a computation's own worker threads (ray casting) do not report;
the loop that collects their chunks does.
"""
from __future__ import annotations

import threading
import time
from contextlib import contextmanager

TICK = 0.2          # seconds between two ticks passed on


class Cancelled(Exception):
    """Raised (by the caller's callback) when the computation is to stop."""


class _Reporter:
    def __init__(self, callback):
        self.callback = callback
        self.scopes = [(0.0, 1.0)]
        self.span = (0.0, 0.0)
        self.message = ""
        self.last = time.monotonic()
        self.high = 0.0           # never reported lower: a bar that goes back helps nobody

    def _pass(self, f):
        self.high = max(self.high, f)
        if self.callback(self.high, self.message) is False:
            raise Cancelled(self.message)

    def _global(self, f):
        lo, hi = self.scopes[-1]
        return lo + (hi - lo) * min(max(float(f), 0.0), 1.0)

    def report(self, frac, message, until):
        self.span = (self._global(frac), self._global(frac if until is None else until))
        self.message = str(message)
        self.last = time.monotonic()
        self._pass(self.span[0])

    def tick(self, done):
        now = time.monotonic()
        if now - self.last < TICK:
            return
        self.last = now
        lo, hi = self.span
        self._pass(lo if done is None else lo + (hi - lo) * min(max(float(done), 0.0), 1.0))


_local = threading.local()


def _current():
    stack = getattr(_local, "stack", None)
    return stack[-1] if stack else None


@contextmanager
def reporting(callback):
    """Report this thread's computation to ``callback`` (None: to nobody)."""
    if callback is None:
        yield
        return
    stack = getattr(_local, "stack", None)
    if stack is None:
        stack = _local.stack = []
    stack.append(_Reporter(callback))
    try:
        yield
    finally:
        stack.pop()


@contextmanager
def scope(lo, hi):
    """Map the fractions reported inside into [lo, hi] of the current stage's whole."""
    rep = _current()
    if rep is None:
        yield
        return
    a, b = rep._global(lo), rep._global(hi)
    rep.scopes.append((a, b))
    try:
        yield
    finally:
        rep.scopes.pop()


def report(frac, message, until=None):
    """A stage starts: it spans [frac, until] (default: frac) of the current scope."""
    rep = _current()
    if rep is not None:
        rep.report(frac, message, until)


def tick(done=None):
    """Between chunks of work: ``done`` of the current stage done (None: not known)."""
    rep = _current()
    if rep is not None:
        rep.tick(done)


def active() -> bool:
    return _current() is not None


def chunked(fn, items, threads=1):
    """``[fn(x) for x in items]`` on ``threads`` threads (numpy and Embree release the GIL), in
    order, with a tick after each chunk; on a cancel the chunks not started are dropped (the
    running ones finish: one chunk each)."""
    items = list(items)
    n = len(items)
    if threads <= 1 or n <= 1:
        out = []
        for i, x in enumerate(items):
            out.append(fn(x))
            tick((i + 1) / n)
        return out
    from concurrent.futures import ThreadPoolExecutor
    pool = ThreadPoolExecutor(threads)
    try:
        out = []
        for i, r in enumerate(pool.map(fn, items)):
            out.append(r)
            tick((i + 1) / n)
        return out
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
